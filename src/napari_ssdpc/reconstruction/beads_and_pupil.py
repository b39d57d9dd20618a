"""The joint fit of beads' spheres and the pupil's terms over the beads' regions of a frame
(:mod:`~napari_ssdpc.reconstruction.pupil_fit` starts it and reports it; docs/aberrations.md).

With the beads' spheres s (centre, radius, Δn) and the pupil's terms θ (the objective's Zernike
coefficients c_j and one defocus δ common to the views, added to each view's d0_k), the weighted
residuals of the multislice views over every bead's region, W (I_k(s; θ)/I0_k − m_k), are minimised
in s and θ together by Gauss-Newton with a trust region (``scipy.optimize.least_squares``), the
Jacobian by forward differences; its covariance gives the terms' uncertainties.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from napari_ssdpc.errors import Cancelled
from napari_ssdpc.physics.multislice_source import square_roi
from napari_ssdpc.reconstruction.bead import Bead
from napari_ssdpc.reconstruction.bead_groups import report_beads
from napari_ssdpc.reconstruction.bead_search import (
    DN_LIMIT,
    FINE_DZ_UM,
    MIN_RADIUS_PX,
    SCALE,
    BeadRegion,
    Stopped,
    overlap_groups,
)
from napari_ssdpc.reconstruction.sphere_volume import spheres_volume

__all__ = ["NOLL", "STEPS", "BeadsAndPupil", "Fitted"]

#: The objective's terms fitted by default (Noll): astigmatism 5-6, coma 7-8, primary spherical 11.
NOLL = (5, 6, 7, 8, 11)
#: The pupil's terms enter the fit's parameters in steps of this many waves (as the spheres' in µm
#: and hundredths of Δn: steps of one size matter alike).
WAVE_SCALE = 0.1
#: The planes of a bead's region reach this far above and below it, µm.
REGION_MARGIN_UM = 3.0
#: Step of the Jacobian's forward differences, in the parameters' scaled units (0.01 µm, 0.0001 in Δn,
#: 0.001 waves): far above the float32 models' rounding, far below the terms' uncertainty.
DIFF_STEP = 0.01
#: Most evaluations of the residuals of a fit.
STEPS = 25
#: The fit has converged when a step lowers the misfit by less than this fraction.
FTOL = 1e-4


@dataclass(frozen=True)
class Fitted:
    """The end of a fit: parameters (:meth:`BeadsAndPupil.pack`), ½ Σ r², whether it converged, the
    Jacobian of the free parameters there (N, F) and their indices."""

    q: np.ndarray
    cost: float
    converged: bool
    jac: np.ndarray
    free: list


class BeadsAndPupil:
    """The misfit of beads' spheres and the pupil's terms over the beads' regions, and its fit.

    Parameters
    ----------
    measurements : Measurements
        The views' front end (its grid, mask, lenslets and multislice model).
    views : ndarray, (K, H, W)
        The flat-fielded views of the bead frame.
    spheres : ndarray, (B, 5)
        The beads' start (x, y, z, R, Δn), µm.
    settings : MultisliceSettings
        The model's sampling and the region's margin.
    noll : sequence of int
        The objective's fitted terms.
    base_zernike : sequence of float
        The optics' own coefficients (Noll from 1), waves: the fitted terms replace theirs.
    defocus0 : array_like, (K,), optional
        Each view's defocus d0_k, waves: the fit moves all of them by one common δ (the MLA's distance
        from the Fourier plane; what differs between the views, their focal lengths, the white frame's
        rims measure, :mod:`~napari_ssdpc.calibration.view_focus`); default 0.
    backend : optional
        Where the models run.

    Attributes
    ----------
    defocus0 : ndarray, (K,)
        May be set between fits (e.g. to the given optics' defocus).
    """

    def __init__(self, measurements, views, spheres, settings, noll=NOLL, base_zernike=(), defocus0=None, backend=None):
        self.noll = tuple(int(j) for j in noll)
        self.spheres = np.asarray(spheres, float).reshape(-1, 5)
        self.regions: list[tuple[list[int], BeadRegion]] = []
        for group in overlap_groups(self.spheres, settings.roi_margin_um):
            s = self.spheres[group]
            x0, x1 = np.min(s[:, 0] - s[:, 3]), np.max(s[:, 0] + s[:, 3])
            y0, y1 = np.min(s[:, 1] - s[:, 3]), np.max(s[:, 1] + s[:, 3])
            side = max(x1 - x0, y1 - y0) + 2 * settings.roi_margin_um
            roi = square_roi(measurements.x_um, measurements.y_um, ((x0 + x1) / 2, (y0 + y1) / 2), side)
            lo = float(np.min(s[:, 2] - s[:, 3])) - REGION_MARGIN_UM
            hi = float(np.max(s[:, 2] + s[:, 3])) + REGION_MARGIN_UM
            self.regions.append((group, BeadRegion(measurements, views, roi, lo, hi, FINE_DZ_UM, settings, backend)))
        self.views_k = self.regions[0][1].model.view_shape[0]
        self.defocus0 = np.zeros(self.views_k) if defocus0 is None else np.asarray(defocus0, float).reshape(-1)
        base = list(base_zernike) + [0.0] * max(0, max(self.noll) - len(base_zernike))
        self._base = np.asarray(base, float)
        self.pixels = sum(float(np.sum(r.model.bk.to_host(r.weight))) for _, r in self.regions)

    # parameters: the spheres in their scaled units, then the pupil's terms in WAVE_SCALE
    def pack(self, spheres, zernike, delta: float = 0.0) -> np.ndarray:
        """The fit's parameter vector.

        Parameters
        ----------
        spheres : array_like, (B, 5)
            (x, y, z, R, Δn), µm.
        zernike : array_like, (J,)
            The fitted objective terms, waves.
        delta : float
            The views' common defocus δ added to :attr:`defocus0`, waves.

        Returns
        -------
        ndarray, (5 B + J + 1,)
            In scaled units (the spheres' :data:`~napari_ssdpc.reconstruction.bead_search.SCALE`,
            the pupil's :data:`WAVE_SCALE`).
        """
        return np.concatenate([(np.asarray(spheres) / SCALE).ravel(), np.r_[zernike, delta] / WAVE_SCALE])

    def unpack(self, q):
        """The spheres and the pupil's terms of a parameter vector.

        Parameters
        ----------
        q : ndarray, (5 B + J + 1,)
            As :meth:`pack` returns.

        Returns
        -------
        spheres : ndarray, (B, 5)
        zernike : ndarray, (J,)
            Waves.
        defocus : ndarray, (K,)
            Every view's d0_k + δ, waves.
        """
        b = len(self.spheres)
        terms = np.asarray(q[5 * b :]) * WAVE_SCALE
        return np.asarray(q[: 5 * b]).reshape(b, 5) * SCALE, terms[: len(self.noll)], self.defocus0 + terms[-1]

    def _set_pupil(self, zernike, defocus) -> None:
        coeffs = self._base.copy()
        coeffs[np.asarray(self.noll) - 1] = zernike
        for _, r in self.regions:
            r.model.set_pupil_phase(coeffs, defocus)

    def _region_residuals(self, k: int, spheres) -> np.ndarray:
        """The weighted residuals W (I/I0 − m) of region ``k`` under the pupil set, one flat vector."""
        group, r = self.regions[k]
        m = r.model
        vol = spheres_volume(spheres[group], r.z_um, m.y_um, m.x_um, r.dz)
        res = (m.views(vol) - r.measured) * m.xp.sqrt(r.weight)
        return np.asarray(m.bk.to_host(res), float).ravel()

    def residuals(self, q) -> list[np.ndarray]:
        """The weighted residuals of every region.

        Parameters
        ----------
        q : ndarray
            The parameters (:meth:`pack`).

        Returns
        -------
        list of ndarray
            W (I/I0 − m) of each region, flattened (flat-field units).
        """
        spheres, zernike, defocus = self.unpack(q)
        self._set_pupil(zernike, defocus)
        return [self._region_residuals(k, spheres) for k in range(len(self.regions))]

    def jacobian(self, q, free, base: list[np.ndarray]) -> np.ndarray:
        """∂residuals/∂q by forward differences of :data:`DIFF_STEP` (a sphere moves only its region's views).

        Parameters
        ----------
        q : ndarray
            The parameters (:meth:`pack`).
        free : list of int
            The parameters differentiated.
        base : list of ndarray
            :meth:`residuals` at ``q``.

        Returns
        -------
        ndarray, (N, len(free))
            Per scaled unit of each parameter.
        """
        spheres, zernike, defocus = self.unpack(q)
        owner = {i: k for k, (group, _) in enumerate(self.regions) for i in group}
        cols: dict[int, np.ndarray] = {}
        self._set_pupil(zernike, defocus)
        for i in (i for i in free if i < 5 * len(spheres)):  # a sphere moves its own region's views
            k = owner[i // 5]
            step = np.zeros(len(q))
            step[i] = DIFF_STEP
            col = [np.zeros_like(r) for r in base]
            col[k] = (self._region_residuals(k, self.unpack(q + step)[0]) - base[k]) / DIFF_STEP
            cols[i] = np.concatenate(col)
        for i in (i for i in free if i >= 5 * len(spheres)):
            step = np.zeros(len(q))
            step[i] = DIFF_STEP
            cols[i] = (np.concatenate(self.residuals(q + step)) - np.concatenate(base)) / DIFF_STEP
        return np.stack([cols[i] for i in free], axis=1)

    def free(self, fixed_dn, hold_pupil: bool) -> list[int]:
        """The parameters a fit moves.

        Parameters
        ----------
        fixed_dn : float or None
            The beads' Δn when known (not moved).
        hold_pupil : bool
            The pupil's terms not moved.

        Returns
        -------
        list of int
            Indices into the parameter vector.
        """
        b = len(self.spheres)
        n = 5 * b + len(self.noll) + 1
        return [
            i
            for i in range(n)
            if not ((fixed_dn is not None and i < 5 * b and i % 5 == 4) or (hold_pupil and i >= 5 * b))
        ]

    def _bounds(self, free, fixed_dn) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of the free parameters: each Δn of its sign, each radius above half a
        model pixel, the pupil's terms within ±2 waves."""
        b = len(self.spheres)
        lo, hi = np.full(len(free), -np.inf), np.full(len(free), np.inf)
        radius_min = MIN_RADIUS_PX * self.regions[0][1].model.dx / SCALE[3]
        for n, i in enumerate(free):
            if i >= 5 * b:
                lo[n], hi[n] = -2.0 / WAVE_SCALE, 2.0 / WAVE_SCALE
            elif i % 5 == 3:
                lo[n] = radius_min
            elif i % 5 == 4:
                lo[n], hi[n] = (
                    (0.0, DN_LIMIT / SCALE[4]) if self.spheres[i // 5, 4] > 0 else (-DN_LIMIT / SCALE[4], 0.0)
                )
        return lo, hi

    def fit(self, q0, *, fixed_dn=None, hold_pupil=False, steps=STEPS, should_stop=None) -> Fitted:
        """Gauss-Newton with a trust region (Levenberg-Marquardt-like, ``scipy.optimize.least_squares``)
        from ``q0``: the pupil's terms and the beads' depths are strongly coupled (spherical aberration
        moves a bead's focus), a valley that a gradient method crosses in hundreds of steps and the
        Jacobian's curvature in a few.

        Parameters
        ----------
        q0 : ndarray
            The start (:meth:`pack`).
        fixed_dn : float, optional
            Every bead's Δn, when known (held).
        hold_pupil : bool
            Fit the spheres alone (the pupil held at ``q0``'s).
        steps : int
            Most evaluations of the residuals (each accepted one also costs a Jacobian).
        should_stop : callable, optional
            True stops the fit (:class:`~napari_ssdpc.errors.Cancelled`).

        Returns
        -------
        Fitted
        """
        free = self.free(fixed_dn, hold_pupil)
        q0 = np.asarray(q0, float).copy()
        lo, hi = self._bounds(free, fixed_dn)
        last: dict = {}

        def full(x):
            q = q0.copy()
            q[free] = x
            return q

        def fun(x):
            if should_stop is not None and should_stop():
                raise Stopped
            last["x"], last["r"] = x.copy(), self.residuals(full(x))
            return np.concatenate(last["r"])

        def jac(x):
            base = last["r"] if "x" in last and np.array_equal(last["x"], x) else self.residuals(full(x))
            return self.jacobian(full(x), free, base)

        try:
            r = least_squares(
                fun, np.clip(q0[free], lo + 1e-9, hi - 1e-9), jac=jac, bounds=(lo, hi), method="trf",
                x_scale="jac", max_nfev=steps, ftol=FTOL, xtol=1e-4, gtol=1e-8,
            )  # fmt: skip
        except Stopped:
            raise Cancelled("the fit of the optics was stopped") from None
        return Fitted(full(r.x), float(r.cost), r.status > 0, r.jac, free)

    def sigmas(self, fitted: Fitted, noise: float) -> np.ndarray:
        """The parameters' uncertainties, σ sqrt(diag (JᵀJ)⁻¹), in their own units (µm, Δn, waves; 0 where held).

        Parameters
        ----------
        fitted : Fitted
        noise : float
            The views' noise σ, flat-field units.
        """
        jac = np.asarray(fitted.jac, float)
        try:
            cov = np.linalg.inv(jac.T @ jac)
            var = np.diag(cov)
        except np.linalg.LinAlgError:
            var = np.full(jac.shape[1], np.inf)
        out = np.zeros(len(fitted.q))
        out[fitted.free] = noise * np.sqrt(np.where(var >= 0, var, np.inf))
        b = len(self.spheres)
        return out * np.r_[np.tile(SCALE, b), np.full(len(fitted.q) - 5 * b, WAVE_SCALE)]

    def beads(self, q, converged: bool, noise: float, optics, settings) -> list[Bead]:
        """The beads of a fit with their checks (the pupil set to the fit's).

        Parameters
        ----------
        q : ndarray
            The parameters (:meth:`pack`).
        converged : bool
            Whether the fit converged.
        noise : float
            The views' noise σ.
        optics : Optics
            The medium's index and the objective's NA.
        settings : MultisliceSettings
            The model's share of the stop.

        Returns
        -------
        list of Bead
            In the order of the spheres.
        """
        spheres, zernike, defocus = self.unpack(q)
        self._set_pupil(zernike, defocus)
        out: list[Bead | None] = [None] * len(spheres)
        for group, r in self.regions:
            for i, bead in zip(group, report_beads(r, spheres[group], converged, noise, optics, settings)):
                out[i] = bead
        return [b for b in out if b is not None]

    def residual_over_noise(self, cost: float, noise: float) -> float:
        """A misfit as the mean squared residual per pixel over the noise variance.

        Parameters
        ----------
        cost : float
            ½ Σ r² over every region.
        noise : float
            The views' noise σ.

        Returns
        -------
        float
        """
        return 2 * cost / max(self.pixels, 1.0) / noise**2
