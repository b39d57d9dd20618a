"""Reconstruction settings: the z grid, the phase method and its parameters, the device.

These are the user's choices for one run, apart from the instrument (:mod:`.optics`). The CLI
builds its options, choices and help defaults from these fields, the napari dock builds its
controls from them, and a run configuration file (:mod:`.config`) stores them.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_validator

from napari_ssdpc.settings.base import SettingsModel, bounded

__all__ = ["DEFAULT_ALPHA", "MAX_PLANES", "PHASE_METHODS", "SIGNS", "TRANSFER_MODELS", "ReconstructionSettings"]

#: 'tv': 3D inversion of all views' defocused WOTFs with total variation, the sign of Δn, a bound
#: and the field stop (ADMM); 'wotf': the same operators with Tikhonov (linear, fast); 'rl': the
#: paper's route (Richardson-Lucy per half, DPC per slice, 2D Tikhonov with the DPC transfer function).
PHASE_METHODS = ("tv", "wotf", "rl")
#: The sign of Δn against the medium: cells in water are denser, PMMA beads in oil lighter.
SIGNS = ("auto", "denser", "lighter", "any")
TRANSFER_MODELS = ("lenslet", "paper")
#: Tikhonov alpha per method: 'rl' on the |H_DPC|² scale of paper Eq. 7, 'wotf' relative to the
#: strongest view's |H|² summed over z (docs/validation.md).
DEFAULT_ALPHA = {"tv": 0.1, "wotf": 0.1, "rl": 0.01}
#: More planes than this is almost always a wrong unit or a typo in the z range.
MAX_PLANES = 2001


class ReconstructionSettings(SettingsModel):
    """How to reconstruct: z range and spacing (µm), phase method, transfer model, iterations."""

    z_min_um: float = bounded(-80.0, -5000.0, 5000.0, "first plane, µm from the focal plane (z > 0: farther)")
    z_max_um: float = bounded(80.0, -5000.0, 5000.0, "last plane, µm from the focal plane")
    dz_um: float = bounded(1.0, 0.05, 100.0, "plane spacing, µm")
    method: Literal["tv", "wotf", "rl"] = Field("tv", description="phase method (docs/validation.md compares them)")
    model: Literal["lenslet", "paper"] = Field("lenslet", description="transfer-function model")
    rl_iterations: int = bounded(15, 1, 500, "Richardson-Lucy iterations (the 'rl' method, DPC and stacks)")
    tikhonov_alpha: float | None = bounded(
        None, 1e-8, 1e6, "Tikhonov regularisation; empty: the method's default (wotf 0.1, rl 0.01)"
    )
    sign: Literal["auto", "denser", "lighter", "any"] = Field(
        "auto", description="sign of Δn against the medium ('tv'); auto: the one the data support"
    )
    dn_max: float = bounded(0.3, 1e-3, 2.0, "largest |Δn| the sample may have ('tv')")
    tv_lambda: float | None = bounded(
        None, 1e-3, 1e3, "TV weight relative to the noise-based choice ('tv'); empty: automatic (1)"
    )
    tv_iterations: int = bounded(60, 1, 2000, "most ADMM iterations ('tv')")
    refraction_increment_um3_pg: float = bounded(
        0.19, 0.05, 0.5, "specific refraction increment for the dry mass, µm³/pg"
    )
    device: Literal["cpu", "gpu"] = Field("cpu", description="cpu (NumPy) or gpu (CuPy, napari-ssdpc[gpu])")

    @model_validator(mode="after")
    def _z_grid(self) -> ReconstructionSettings:
        if self.z_max_um < self.z_min_um:
            raise ValueError(
                f"z range is empty: z_max_um {self.z_max_um} < z_min_um {self.z_min_um}; give ZMIN <= ZMAX"
            )
        planes = math.floor((self.z_max_um - self.z_min_um) / self.dz_um + 1e-6) + 1
        if planes > MAX_PLANES:
            raise ValueError(
                f"{planes} planes from z {self.z_min_um:g} to {self.z_max_um:g} µm every {self.dz_um:g} µm "
                f"(at most {MAX_PLANES}); narrow the z range or take a larger dz_um"
            )
        return self

    @property
    def alpha(self) -> float:
        """The Tikhonov alpha in use: the given one, else the method's default."""
        return DEFAULT_ALPHA[self.method] if self.tikhonov_alpha is None else self.tikhonov_alpha
