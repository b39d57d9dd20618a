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
    def build(cls, setup: Setup, progress=None) -> RlMethod:
        """Nothing beyond the stacks' operators.

        Parameters
        ----------
        setup : Setup
        progress : callable, optional
            ``progress(done, total, label)`` while the operators are built.

        Returns
        -------
        RlMethod
        """
        return cls(setup)

    def solve(self, views, stacks=None, *, warm=None, progress=None, should_stop=None) -> Solution:
        """Paper Eq. 7 on every slice of the DPC stacks.

        Parameters
        ----------
        views : ndarray, float32, (K, ny, nx)
            Flat-fielded views.
        stacks : Stacks, optional
            The frame's directional stacks (required).
        warm : Solution, optional
            Unused: the inverse is linear.
        progress, should_stop : callable, optional
            Per iteration.

        Returns
        -------
        Solution
            Phase per slab (Z, ny, nx), rad.
        """
        if stacks is None:
            raise ValueError("the 'rl' method takes its phase from the directional stacks")
        h = [stacks.h_dpc["ud"], stacks.h_dpc["lr"]]
        dpc = [stacks.dpc["ud"], stacks.dpc["lr"]]
        return Solution(tikhonov_phase(dpc, h, self.setup.settings.rl.alpha) * self.setup.views.mask)

    def settings(self) -> dict:
        """The Tikhonov α and the DPC transfer model."""
        rl = self.setup.settings.rl
        return {"tikhonov_alpha": rl.alpha, "model": rl.model}
