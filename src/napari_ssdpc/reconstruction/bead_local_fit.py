"""The bead fit's local fit (:mod:`~napari_ssdpc.reconstruction.beads`): L-BFGS-B on the misfit of
spheres over a :class:`~napari_ssdpc.reconstruction.bead_search.BeadRegion`, from a start of the scan,
with a stop where the single-precision misfit no longer resolves its steps."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from napari_ssdpc.reconstruction.bead_search import DN_LIMIT, MIN_RADIUS_PX, SCALE, BeadRegion, Stopped

__all__ = ["PATIENCE", "local_fit"]

#: A local fit ends when this many evaluations in a row have not lowered its best misfit by more than
#: its tolerance: its line search is then probing steps below what the single-precision misfit
#: resolves. Without this stop the fits of the PMMA bead spent 23 of the full fit's 36 evaluations
#: and about 90 of the coarse fits' 154 at one point (docs/beads.md).
PATIENCE = 5


def local_fit(region: BeadRegion, spheres, sign: np.ndarray, iterations: int, z_range, should_stop=None, fixed_dn=None):
    """L-BFGS-B from the given spheres, each with its sign of Δn held and its centre within the volume.

    Parameters
    ----------
    region : BeadRegion
    spheres : ndarray, (B, 5)
        The start.
    sign : ndarray, (B,)
        +1 or −1: the sign of each sphere's Δn.
    iterations : int
        Most iterations.
    z_range : (float, float)
        The depths a centre may take, µm (the volume's first and last plane).
    should_stop : callable, optional
        True stops the fit (:class:`Stopped`).
    fixed_dn : float, optional
        Every sphere's Δn, when known (held at it).

    Returns
    -------
    spheres : ndarray, (B, 5)
    value : float
        Their misfit.
    converged : bool
        The fit ended on its convergence test, or on :data:`PATIENCE` evaluations in a row that did
        not lower its best misfit by more than that test's tolerance.
    """
    b = len(spheres)
    radius_min = MIN_RADIUS_PX * region.model.dx
    bounds = []
    for s in sign:
        dn_bounds = (0.0, DN_LIMIT) if s > 0 else (-DN_LIMIT, 0.0)
        dn_bounds = dn_bounds if fixed_dn is None else (fixed_dn, fixed_dn)
        bounds += [(None, None)] * 2 + [tuple(z_range), (radius_min, None), tuple(v / SCALE[4] for v in dn_bounds)]

    # stop when an iteration lowers the misfit by less than a tenth of a noise variance over all data
    ftol = 0.1 / max(float(region.model.xp.sum(region.weight)), 1.0)
    best = _Best(ftol)

    def fun(q):
        if should_stop is not None and should_stop():
            raise Stopped
        p = q.reshape(b, 5) * SCALE
        value, grad = region.misfit_and_gradient(p)
        best.record(value, p)
        return value, (grad * SCALE).ravel()

    options = {"maxiter": iterations, "ftol": ftol}
    try:
        r = minimize(fun, (spheres / SCALE).ravel(), jac=True, method="L-BFGS-B", bounds=bounds, options=options)
    except _Stalled:
        return best.spheres, best.value, True
    return r.x.reshape(b, 5) * SCALE, float(r.fun), bool(r.success)


class _Stalled(Exception):
    """:data:`PATIENCE` evaluations in a row did not lower the best misfit."""


class _Best:
    """The best evaluation of a local fit so far; :class:`_Stalled` after :data:`PATIENCE` in a row
    that lowered it by no more than ``ftol`` of its value (L-BFGS-B's own test of an iteration)."""

    def __init__(self, ftol: float):
        self.ftol, self.value, self.stalls = ftol, math.inf, 0
        self.spheres: np.ndarray | None = None

    def record(self, value: float, spheres) -> None:
        gain = self.value - value
        self.stalls = 0 if gain > self.ftol * max(abs(value), 1.0) else self.stalls + 1
        if gain > 0:
            self.value, self.spheres = float(value), np.array(spheres, float)
        if self.stalls >= PATIENCE:
            raise _Stalled
