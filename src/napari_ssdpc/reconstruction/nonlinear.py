"""One solver for every nonlinear model of the views: accelerated projected gradient on the backend.

A nonlinear model (:class:`NonlinearModel`: the multislice model of
:mod:`napari_ssdpc.physics.views_multislice`; a multi-layer Born or SSNP model is another file that
keeps the same protocol) predicts the flat-fielded views of a Δn volume and gives the gradient of
their misfit. :class:`Fit` states the problem every such method solves,

    minimise  ½ Σ_k ‖W (I_k(Δn) / I0_k − m_k)‖² + μ TV_ε(Δn)   subject to  lo ≤ Δn ≤ hi, Δn = 0 outside the field stop,

and :func:`projected_gradient` solves it: FISTA with backtracking on the quadratic upper bound
and a restart of the momentum whenever the objective rises (Beck and Teboulle, SIAM J. Imaging
Sci. 2009; O'Donoghue and Candès, Found. Comput. Math. 2015), stopped by the discrepancy principle
(the objective below ``enough``: the data are fitted to their noise and the model's error) or by a
relative change below ``tolerance``. Every array stays on the model's backend (NumPy or CuPy),
in float32.

The unknowns are either on the views' grid (each view pixel stands for the ``refine`` x ``refine``
samples of the model grid under it) or on the model's own grid (:class:`Unknowns`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

from napari_ssdpc.backend import Backend
from napari_ssdpc.errors import SsdpcError

__all__ = ["Fit", "FitResult", "NonlinearModel", "Unknowns", "discrepancy_stop", "projected_gradient", "smoothed_tv"]

#: ε of the smoothed TV, Δn per µm: far below any edge of a sample, so TV_ε is TV where it matters.
TV_EPSILON = 1e-4


@runtime_checkable
class NonlinearModel(Protocol):
    """What the solver needs of a nonlinear model of the views.

    Attributes
    ----------
    bk : Backend
        Where its arrays live.
    shape : tuple of int
        (Z, ny, nx) of the Δn volume it takes (its own grid).
    view_shape : tuple of int
        (K, h, w) of the views it predicts.
    """

    bk: Backend
    shape: tuple[int, ...]
    view_shape: tuple[int, ...]

    def views(self, dn) -> Any:
        """The flat-fielded views (K, h, w) of a Δn volume, on the backend.

        Parameters
        ----------
        dn : ndarray, (Z, ny, nx)
        """
        ...

    def misfit(self, dn, measured, weight=None) -> tuple[float, Any]:
        """½ Σ_k ‖W (views − measured)‖² and its gradient with respect to Δn, on the backend.

        Parameters
        ----------
        dn : ndarray, (Z, ny, nx)
        measured : ndarray, (K, h, w)
        weight : ndarray, broadcastable to (K, h, w), optional
        """
        ...


def discrepancy_stop(settings, contrast: float, noise: float) -> float:
    """Where a nonlinear fit of the views stops, in mean squared residual over the noise variance.

    The discrepancy principle: a fit closer than the noise and the model's own error fits them; the
    model's error is a share (``settings.model_error``) of the views' contrast, larger for a stronger
    object.

    Parameters
    ----------
    settings : MultisliceSettings
        ``stop_residual_over_noise`` and ``model_error``.
    contrast : float
        The views' mean squared contrast (I/I0 − 1)², flat-field units².
    noise : float
        The views' noise σ, flat-field units (0: unknown, the model's share left out).

    Returns
    -------
    float
    """
    share = settings.model_error**2 * contrast / noise**2 if noise > 0 else 0.0
    return settings.stop_residual_over_noise + share


def smoothed_tv(x, voxel_um, eps: float, xp):
    """TV_ε(x) = Σ sqrt(|∇x|² + ε²) and its gradient, isotropic, in physical units.

    Parameters
    ----------
    x : ndarray, (Z, ny, nx)
        Δn.
    voxel_um : (float, float, float)
        (dz, dy, dx), µm: the forward differences are per µm, 0 at the last index (no wrap-around).
    eps : float
        Smoothing, Δn per µm.
    xp : module
        The array module of ``x`` (NumPy or CuPy).

    Returns
    -------
    value : float
        TV_ε, Δn·µm⁻¹ summed over voxels.
    grad : ndarray, like ``x``
        Σ_a D_aᵀ (D_a x / sqrt(|∇x|² + ε²)).
    """
    diffs = []
    for a, h in enumerate(voxel_um):
        d = xp.zeros_like(x)
        xa, da = xp.moveaxis(x, a, 0), xp.moveaxis(d, a, 0)  # views
        da[:-1] = (xa[1:] - xa[:-1]) / h
        diffs.append(d)
    norm = xp.sqrt(sum(d * d for d in diffs) + eps * eps)
    out = xp.zeros_like(x)
    for a, (d, h) in enumerate(zip(diffs, voxel_um)):
        q = xp.moveaxis(d / norm, a, 0)
        o = xp.moveaxis(out, a, 0)  # a view: D_aᵀ q = (q_{i-1} − q_i) / h
        o -= q / h
        o[1:] += q[:-1] / h
    return float(norm.sum()), out


@dataclass(frozen=True)
class Unknowns:
    """The grid of the unknowns: the views' (each pixel ``refine`` x ``refine`` model samples) or
    the model's own (``refine`` = 1 there, or sub-pixel edges free).

    Attributes
    ----------
    refine : int
        Model samples per unknown along x and y (1: the unknowns are the model's samples).
    xp : module
        The array module.
    """

    refine: int
    xp: Any

    def up(self, x):
        """The model's Δn (Z, k·ny, k·nx) of the unknowns.

        Parameters
        ----------
        x : ndarray, (Z, ny, nx)
        """
        k = self.refine
        return x if k == 1 else self.xp.repeat(self.xp.repeat(x, k, axis=1), k, axis=2)

    def down(self, g):
        """The adjoint of :meth:`up`: sums of the model's k x k samples, (Z, ny, nx).

        Parameters
        ----------
        g : ndarray, (Z, k·ny, k·nx)
        """
        k = self.refine
        if k == 1:
            return g
        z, ny, nx = g.shape
        return g.reshape(z, ny // k, k, nx // k, k).sum(axis=(2, 4))


@dataclass
class Fit:
    """One nonlinear fit: the model, the data, the constraints and the TV weight, on the backend.

    Attributes
    ----------
    model : NonlinearModel
    measured : ndarray, float32, (K, h, w)
        The flat-fielded views the model predicts (on the backend).
    weight : ndarray, float32, broadcastable to (K, h, w)
        W² per pixel (0 where a view holds no data).
    unknowns : Unknowns
    lo, hi : float
        The bound of Δn (the sign constraint: one of them 0).
    inside : ndarray, float32, (1, ny, nx) or (Z, ny, nx) on the unknowns' grid
        1 where Δn is free (inside the field stop), 0 where it is held at the medium.
    mu : float
        Weight of TV_ε, (flat-field units)² per (Δn/µm).
    voxel_um : (float, float, float)
        The unknowns' voxel (dz, dy, dx), µm.
    """

    model: NonlinearModel
    measured: Any
    weight: Any
    unknowns: Unknowns
    lo: float
    hi: float
    inside: Any
    mu: float = 0.0
    voxel_um: tuple[float, float, float] = (1.0, 1.0, 1.0)

    @property
    def xp(self):
        """The array module of the fit."""
        return self.model.bk.xp

    def project(self, x):
        """x on C: clipped to [lo, hi], 0 outside the field stop.

        Parameters
        ----------
        x : ndarray, (Z, ny, nx) on the unknowns' grid
        """
        return self.xp.clip(x, self.lo, self.hi) * self.inside

    def residual(self, x):
        """W (I(x) / I0 − m), (K, h, w), on the backend.

        Parameters
        ----------
        x : ndarray, (Z, ny, nx) on the unknowns' grid
        """
        return self.views_and_residual(x)[1]

    def views_and_residual(self, x):
        """The model's views I(x) / I0 and the residual W (I(x) / I0 − m), each (K, h, w), on the backend.

        Parameters
        ----------
        x : ndarray, (Z, ny, nx) on the unknowns' grid

        Returns
        -------
        views, residual : ndarray
        """
        views = self.model.views(self.unknowns.up(x))
        return views, (views - self.measured) * self.xp.sqrt(self.weight)

    def objective(self, x, with_grad: bool = True):
        """The objective at x and, with ``with_grad``, its gradient (None otherwise).

        Parameters
        ----------
        x : ndarray, float32, (Z, ny, nx) on the unknowns' grid
        with_grad : bool

        Returns
        -------
        value : float
        grad : ndarray like x, or None
        """
        if with_grad:
            f, g = self.model.misfit(self.unknowns.up(x), self.measured, self.weight)
            g = self.unknowns.down(g)
        else:
            r = self.residual(x)
            f, g = 0.5 * float(self.xp.sum(r * r)), None
        if self.mu > 0:
            t, gt = smoothed_tv(x, self.voxel_um, TV_EPSILON, self.xp)
            f += self.mu * t
            g = None if g is None else g + self.mu * gt
        return f, g


@dataclass
class FitResult:
    """Where :func:`projected_gradient` ended.

    Attributes
    ----------
    x : ndarray, (Z, ny, nx)
        The solution on the unknowns' grid, on the backend.
    history : dict
        ``objective`` (one value per accepted step, the start first) and ``relative_change``
        (one per iteration, 0 for a restart).
    converged : bool
        Stopped by the discrepancy principle or the tolerance (not by the iteration limit or Stop).
    """

    x: Any
    history: dict = field(default_factory=dict)
    converged: bool = False

    @property
    def iterations(self) -> int:
        """Iterations run (restarts included)."""
        return len(self.history["relative_change"])


def projected_gradient(
    fit: Fit,
    x0,
    *,
    iterations: int,
    tolerance: float,
    enough: float = 0.0,
    progress=None,
    should_stop=None,
    label: str = "fit",
) -> FitResult:
    """Minimise ``fit``'s objective over its constraint set from ``x0`` (FISTA, backtracking, restart).

    Parameters
    ----------
    fit : Fit
    x0 : ndarray, (Z, ny, nx)
        The start on the unknowns' grid (projected first).
    iterations : int
        Most iterations.
    tolerance : float
        Stop when ‖x_new − x‖ / ‖x_new‖ falls below it (after three iterations).
    enough : float
        Stop as soon as the objective is at most this (the discrepancy principle); 0: never.
    progress : callable, optional
        ``progress(done, total, label)`` per accepted step.
    should_stop : callable, optional
        Checked every iteration: True ends the fit where it is.
    label : str
        The progress label.

    Returns
    -------
    FitResult
    """
    xp = fit.xp
    x = fit.project(x0)
    f, g = fit.objective(x)
    history: dict = {"objective": [f], "relative_change": []}
    step = 0.1 * max(float(xp.abs(x).max()), 1e-3) / max(float(xp.abs(g).max()), 1e-30)
    y, fy, gy, t_k, converged = x, f, g, 1.0, False
    for it in range(iterations):
        if should_stop is not None and should_stop():
            break
        if f <= enough:
            converged = True
            break
        while True:  # backtracking on the quadratic upper bound at y
            x_new = fit.project(y - step * gy)
            d = x_new - y
            f_new, _ = fit.objective(x_new, with_grad=False)
            if f_new <= fy + float(xp.sum(gy * d)) + float(xp.sum(d * d)) / (2 * step) or step < 1e-30:
                break
            step *= 0.5
        if not math.isfinite(f_new):  # never hand on nonsense
            raise SsdpcError(
                f"the {label} fit diverged at iteration {it + 1} (misfit {f:.4g}, then {f_new}); nothing was "
                "written: reconstruct with 'tv', or with a smaller source_spacing_na"
            )
        change = float(xp.linalg.norm(x_new - x)) / max(float(xp.linalg.norm(x_new)), 1e-30)
        if f_new > f:  # the objective rose: restart the momentum from the last point
            t_k, y = 1.0, x
            fy, gy = fit.objective(y)
            history["relative_change"].append(0.0)
            continue
        t_next = (1 + math.sqrt(1 + 4 * t_k * t_k)) / 2
        y = x_new + ((t_k - 1) / t_next) * (x_new - x)
        x, f, t_k = x_new, f_new, t_next
        fy, gy = fit.objective(y)
        step *= 1.5  # let the step grow back
        history["objective"].append(f)
        history["relative_change"].append(change)
        if progress is not None:
            progress(it + 1, iterations, label)
        if change < tolerance and it > 2:
            converged = True
            break
    return FitResult(x, history, converged)
