"""What the 'tv' solver did: iterations, objective, λ and noise, for metadata and plots."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["TvReport"]


@dataclass
class TvReport:
    """What the solver did, for the metadata and the convergence plot.

    Attributes
    ----------
    iterations : int
        ADMM iterations run.
    converged : bool
        The relative change fell below the tolerance.
    objective : list of float
        ½‖Aφ − c‖² + λ TV(φ) per iteration (the data term in noise-weighted contrast units).
    relative_change : list of float
        ‖φ_i − φ_{i−1}‖ / ‖φ_i‖ per iteration.
    noise : float
        The views' noise, contrast units (rms per pixel, weighted mean over the views).
    lam : float
        The λ used (absolute, in the units of the objective).
    lam_auto : bool
        λ came from the noise.
    sign : str
        The sign constraint used ('denser', 'lighter' or 'any').
    residual_over_noise : float
        ‖Aφ − c‖² over the band divided by its expectation from the noise alone.
    sign_objectives : dict
        With sign 'auto': the objective each sign's probe reached.
    warm : bool
        The solve started where the previous frame's ended.
    temporal_weight : float
        Weight of the temporal prior used, relative to the sparsity's (0: none, as on a first frame).
    state : TvState or None
        Where the solve ended (the start of the next frame); not metadata.
    """

    iterations: int = 0
    converged: bool = False
    objective: list = field(default_factory=list)
    relative_change: list = field(default_factory=list)
    noise: float = float("nan")
    lam: float = float("nan")
    lam_auto: bool = True
    sign: str = "any"
    residual_over_noise: float = float("nan")
    sign_objectives: dict = field(default_factory=dict)
    warm: bool = False
    temporal_weight: float = 0.0
    state: Any = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        """Plain numbers for the result's metadata."""
        return {
            "tv_iterations_run": self.iterations,
            "tv_converged": self.converged,
            "tv_objective_final": self.objective[-1] if self.objective else None,
            "tv_noise": self.noise,
            "tv_lambda": self.lam,
            "tv_lambda_auto": self.lam_auto,
            "tv_sign": self.sign,
            "tv_residual_over_noise": self.residual_over_noise,
            "tv_warm_start": self.warm,
            "tv_temporal_weight": self.temporal_weight,
        }
