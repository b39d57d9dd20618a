"""The 'rl' method, the paper's route: the phase per slice from the DPC stacks (Eq. 7)."""

from __future__ import annotations

from napari_ssdpc.reconstruction.dpc import tikhonov_phase
from napari_ssdpc.reconstruction.methods.base import PhaseMethod, Setup, Solution

__all__ = ["RlMethod"]


class RlMethod(PhaseMethod):
    """Tikhonov phase per slice from the up-down and left-right DPC stacks, with the in-focus DPC
    transfer function of the chosen model (paper Eq. 7); the stacks come from
    :class:`~napari_ssdpc.reconstruction.stacks.DirectionalStacks`."""

    name = "rl"
    uses_stacks = True

    def __init__(self, setup: Setup):
        self.setup = setup

    @classmethod
    def _build(cls, setup, progress):
        return cls(setup)  # nothing beyond the stacks' operators

    def _solve(self, views, stacks, warm, progress, should_stop):
        h = [stacks.h_dpc["ud"], stacks.h_dpc["lr"]]
        dpc = [stacks.dpc["ud"], stacks.dpc["lr"]]
        return Solution(tikhonov_phase(dpc, h, self.setup.settings.rl.alpha) * self.setup.views.mask)

    def settings(self) -> dict:
        """The Tikhonov α and the DPC transfer model."""
        rl = self.setup.settings.rl
        return {"tikhonov_alpha": rl.alpha, "model": rl.model}
