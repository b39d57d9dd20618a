"""The pupil fitted to a frame of beads: the objective's aberration and the views' focus, with the beads'
centres and sizes free (docs/aberrations.md).

A bead's views through an aberrated pupil differ from the nominal ones in a way a change of the bead
cannot copy: spherical aberration and astigmatism blur the views differently at different depths, and
a lenslet's defocus blurs its view without the parallax a change of depth brings. With the beads'
spheres s (centre, radius, Δn) and the pupil's terms θ (the objective's Zernike coefficients c_j, each
view's defocus d_k), the fit minimises the multislice views' misfit over every bead's region,

    L(s, θ) = Σ_regions ½ Σ_k ‖W (I_k(s; θ) / I0_k − m_k)‖²,

jointly in s and θ by L-BFGS-B on the gradient of one adjoint pass
(:meth:`~napari_ssdpc.physics.views_adjoint.ViewsAdjoint.misfit_and_pupil`). L has local minima (a
bead fitted far from its place under a wrong pupil keeps it there), so each start pupil's beads come
from the full bead search (:func:`~napari_ssdpc.reconstruction.beads.measure_beads`) with that pupil;
a blurred white frame gives each view's |d_k| (:mod:`~napari_ssdpc.calibration.view_focus`) but not
its sign, so both signs are started (the second only when the first leaves a bead unexplained: a pupil
of the wrong sign cannot explain them) and the lower misfit is kept.

The terms' uncertainties are the Gauss-Newton covariance σ² (Jᵀ W J)⁻¹ at the fit, with J the views'
derivatives in every parameter (central differences) and σ the views' noise; a term the frame does not
determine (σ above :data:`UNDETERMINED_WAVES`) is refused in one line. Piston, tilt and the objective's
defocus are left out: they move the objects, not the pupil (the beads' centres take them).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from napari_ssdpc.errors import Cancelled, SsdpcError
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
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms

__all__ = ["NOLL", "UNDETERMINED_WAVES", "BeadsAndPupil", "PupilFit"]

#: The objective's terms fitted by default (Noll): astigmatism 5-6, coma 7-8, primary spherical 11.
NOLL = (5, 6, 7, 8, 11)
#: The pupil's terms enter the fit's parameters in steps of this many waves (as the spheres' in µm
#: and hundredths of Δn: steps of one size matter alike).
WAVE_SCALE = 0.1
#: A term whose uncertainty is larger than this, waves, is not determined by the frame.
UNDETERMINED_WAVES = 0.05
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


@dataclass(frozen=True)
class PupilFit:
    """The pupil's terms fitted to a frame of beads, their uncertainties and the beads.

    Attributes
    ----------
    noll : tuple of int
        The objective's fitted terms (Noll indices).
    zernike_waves, zernike_sigma : ndarray, (len(noll),)
        Their coefficients and uncertainties, waves (rms-normalised).
    keys : tuple of (int, int)
        The views' lenslets (row, col).
    defocus_waves : ndarray, (K,)
        Each view's defocus, waves at its sub-aperture's edge.
    defocus_sigma : ndarray, (K,)
        Their uncertainties, waves.
    beads : tuple of Bead
        The beads as fitted with the fitted pupil.
    residual_before, residual_after : float
        The views' mean squared residual over the beads' regions, in noise variances, with the pupil the
        fit started from (the beads fitted again under it) and with the fitted one.
    converged : bool
        The fit ended on its convergence test.
    """

    noll: tuple[int, ...]
    zernike_waves: np.ndarray
    zernike_sigma: np.ndarray
    keys: tuple[tuple[int, int], ...]
    defocus_waves: np.ndarray
    defocus_sigma: np.ndarray
    beads: tuple[Bead, ...]
    residual_before: float
    residual_after: float
    converged: bool

    def aberrations(self, base: Aberrations) -> Aberrations:
        """``base`` with the fitted objective terms and each view's fitted defocus.

        Parameters
        ----------
        base : Aberrations
            The optics' aberrations (their other terms are kept).

        Returns
        -------
        Aberrations
        """
        coeffs = list(base.objective_zernike_waves) + [0.0] * max(0, max(self.noll) - len(base.objective_zernike_waves))
        for j, c in zip(self.noll, self.zernike_waves):
            coeffs[j - 1] = round(float(c), 4)
        terms = {(t.row, t.col): t for t in base.lenslets}
        for (row, col), d in zip(self.keys, self.defocus_waves):
            old = terms.get((row, col), LensletTerms(row=row, col=col))
            terms[(row, col)] = old.model_copy(update={"defocus_waves": round(float(d), 4)})
        return base.model_copy(update={"objective_zernike_waves": tuple(coeffs), "lenslets": tuple(terms.values())})

    def undetermined(self) -> list[str]:
        """The terms whose uncertainty exceeds :data:`UNDETERMINED_WAVES` (names for people)."""
        out = [f"Z{j}" for j, s in zip(self.noll, self.zernike_sigma) if not s <= UNDETERMINED_WAVES]
        bad = [k for k, s in zip(self.keys, self.defocus_sigma) if not s <= UNDETERMINED_WAVES]
        if bad:
            out.append(f"the defocus of {len(bad)} of {len(self.keys)} views")
        return out

    def report(self) -> list[str]:
        """Every term with its uncertainty, and the residual before and after, for people."""
        terms = ", ".join(
            f"Z{j} {c:+.3f} ± {s:.3f}" for j, c, s in zip(self.noll, self.zernike_waves, self.zernike_sigma)
        )
        d, s = self.defocus_waves, self.defocus_sigma
        return [
            f"objective (waves rms): {terms}",
            f"view defocus {np.mean(d):+.3f} waves at the sub-aperture's edge (range {d.min():+.3f} to {d.max():+.3f}, "
            f"± {np.median(s):.3f}; {len(d)} views)",
            f"beads: {len(self.beads)}, residual {self.residual_before:.1f} -> {self.residual_after:.1f} x the noise "
            "(the given pupil -> the fitted one)",
        ]

    def to_dict(self) -> dict:
        """Plain numbers for the calibration's ``optics_fit``."""
        return {
            "noll": list(self.noll),
            "zernike_waves": [float(v) for v in self.zernike_waves],
            "zernike_sigma": [float(v) for v in self.zernike_sigma],
            "defocus_waves": [float(v) for v in self.defocus_waves],
            "defocus_sigma": [float(v) for v in self.defocus_sigma],
            "beads": [b.to_dict() for b in self.beads],
            "residual_before": float(self.residual_before),
            "residual_after": float(self.residual_after),
        }


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
        """The fit's parameter vector of spheres (B, 5), objective terms (J,) and the views' common
        defocus δ (waves) added to :attr:`defocus0`."""
        return np.concatenate([(np.asarray(spheres) / SCALE).ravel(), np.r_[zernike, delta] / WAVE_SCALE])

    def unpack(self, q):
        """Spheres (B, 5), objective terms (J,), every view's defocus d0_k + δ (K,) of a parameter vector."""
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
        """The weighted residuals of every region at parameters ``q`` (:meth:`pack`)."""
        spheres, zernike, defocus = self.unpack(q)
        self._set_pupil(zernike, defocus)
        return [self._region_residuals(k, spheres) for k in range(len(self.regions))]

    def jacobian(self, q, free, base: list[np.ndarray]) -> np.ndarray:
        """∂residuals/∂q of the ``free`` parameters by forward differences of :data:`DIFF_STEP` (a
        sphere's moves only its region's views), (N, len(free))."""
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
        """The parameters a fit moves: not Δn where it is known, not the pupil's terms when held."""
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
        """The beads of parameters ``q`` with their checks (the pupil set to ``q``'s)."""
        spheres, zernike, defocus = self.unpack(q)
        self._set_pupil(zernike, defocus)
        out: list[Bead | None] = [None] * len(spheres)
        for group, r in self.regions:
            for i, bead in zip(group, report_beads(r, spheres[group], converged, noise, optics, settings)):
                out[i] = bead
        return [b for b in out if b is not None]

    def residual_over_noise(self, cost: float, noise: float) -> float:
        """A misfit ½ Σ r² as the mean squared residual per pixel over the noise variance."""
        return 2 * cost / max(self.pixels, 1.0) / noise**2


def start_defocus(keys: Sequence[tuple[int, int]], focus, sign: float, base: Aberrations) -> np.ndarray:
    """Each view's defocus to start from: ``sign`` x the white frame's |d_k| where measured, else the
    optics' own.

    Parameters
    ----------
    keys : sequence of (int, int)
        The views' lenslets.
    focus : FocusFit or None
    sign : float
        +1 or −1.
    base : Aberrations

    Returns
    -------
    ndarray, (K,)
    """
    measured = {} if focus is None else dict(zip(focus.keys, focus.defocus_waves))
    return np.array(
        [sign * float(measured[k]) if k in measured else base.lenslet(*k).defocus_waves for k in keys], float
    )


def with_pupil(cal, zernike_full, keys, defocus):
    """A copy of the calibration whose optics carry the given objective terms and views' defocus."""
    ab = cal.optics.aberrations
    terms = {(t.row, t.col): t for t in ab.lenslets}
    for k, d in zip(keys, defocus):
        old = terms.get(k, LensletTerms(row=k[0], col=k[1]))
        terms[k] = old.model_copy(update={"defocus_waves": round(float(d), 4)})
    new = ab.model_copy(
        update={"objective_zernike_waves": tuple(float(c) for c in zernike_full), "lenslets": tuple(terms.values())}
    )
    return dataclasses.replace(cal, optics=cal.optics.replace(aberrations=new.to_dict()))


def fit_pupil(
    config,
    cal,
    flat,
    frame,
    *,
    focus=None,
    bead_ri: float | None = None,
    noll: Sequence[int] = NOLL,
    steps: int = STEPS,
    name: str = "bead frame",
    progress=None,
    should_stop=None,
) -> PupilFit:
    """Fit the objective's terms and every view's defocus to a frame of beads.

    Parameters
    ----------
    config : RunConfig
        The volume the beads lie in (z range and planes) and the multislice model's sampling; its
        optics' medium index is the beads' medium.
    cal : Calibration
        With the condenser fitted (:func:`~napari_ssdpc.reconstruction.optics_fit.fit_optics`).
    flat : ndarray, (H, W)
        The flat frame.
    frame : ndarray, (H, W)
        The raw frame of beads, camera units.
    focus : FocusFit, optional
        Each view's |defocus| from the white frame's rims: when blurred, the fit starts from it with
        each sign and keeps the better.
    bead_ri : float, optional
        The beads' index, when known (their Δn is held).
    noll : sequence of int
        The objective's terms fitted.
    steps : int
        Most evaluations of the residuals in each fit.
    name : str
        The frame's name in messages.
    progress : callable, optional
        ``progress(done, total, label)`` after each stage.
    should_stop : callable, optional
        True stops the fit (:class:`~napari_ssdpc.errors.Cancelled`).

    Returns
    -------
    PupilFit

    Raises
    ------
    SsdpcError
        No bead in the frame, beads of another index than ``bead_ri``, a fit that does not converge or
        does not explain the beads, or terms the frame does not determine (one line each).
    """
    from napari_ssdpc.reconstruction.beads import first_answer, fit_beads
    from napari_ssdpc.reconstruction.reconstructor import Reconstructor

    medium = config.optics.medium_index
    cal = dataclasses.replace(cal, optics=cal.optics.replace(medium_index=medium))
    given = cal.optics.aberrations
    config = config.replace_reconstruction(method="tv").replace(
        optics=config.optics.replace(aberrations=Aberrations()).to_dict()
    )
    bead_dn = None if bead_ri is None else float(bead_ri) - medium
    if bead_dn is not None and not (abs(bead_dn) >= 1e-3 and abs(bead_dn) < DN_LIMIT):
        raise SsdpcError(
            f"--bead-ri {bead_ri} in a medium of {medium}: the beads must differ from the medium by 0.001 to "
            f"{DN_LIMIT} (set --medium-index to the beads' medium)"
        )
    signs = (1.0, -1.0) if focus is not None and focus.blurred else (0.0,)
    total = 3 * len(signs) + 1  # a start that explains every bead ends the starts early
    done = 0

    def step(label: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total, label)

    base_z = np.zeros(max(max(noll), len(given.objective_zernike_waves)))
    base_z[: len(given.objective_zernike_waves)] = given.objective_zernike_waves
    zernike0 = base_z[np.asarray(noll) - 1]
    best = None
    for sign in signs:
        keys = [(ln.row, ln.col) for ln in cal.lenslets]
        defocus = start_defocus(keys, focus, sign, given) if sign else None
        start = cal if defocus is None else with_pupil(cal, base_z, keys, defocus)
        rec = Reconstructor(config, start, flat=flat)
        views, _ = rec.views.measure(frame, name)
        dn, noise = first_answer(rec, views, should_stop=should_stop)
        step("the first answer")
        settings = config.reconstruction.multislice
        beads = fit_beads(
            rec.views, views, dn, rec.z_um, noise=noise, optics=rec.optics, settings=settings,
            should_stop=should_stop,
        )  # fmt: skip
        step("the beads under the start pupil")
        if not beads:
            raise SsdpcError(f"no bead found in {name}: give a frame of beads (its first answer holds no object)")
        spheres = np.array(
            [[*b.centre_um, b.diameter_um / 2, b.delta_n if bead_dn is None else bead_dn] for b in beads]
        )
        view_keys = [(ln.row, ln.col) for ln in rec.views.lenslets]
        d0 = start_defocus(view_keys, focus if sign else None, sign or 1.0, given)
        job = BeadsAndPupil(rec.views, views, spheres, settings, noll, base_z, d0, rec.backend)
        fitted = job.fit(job.pack(spheres, zernike0), fixed_dn=bead_dn, steps=steps, should_stop=should_stop)
        step("beads and pupil together")
        if best is None or fitted.cost < best[0].cost:
            best = (fitted, job, noise, rec)
        # a pupil of the wrong sign cannot explain the beads: the first start that explains every bead
        # is the answer (the other's search and fit, half the time, are saved)
        if fitted.converged and all(
            b.explained for b in job.beads(fitted.q, True, noise, rec.optics, config.reconstruction.multislice)
        ):
            break
    assert best is not None  # signs holds at least one start
    fitted, job, noise, rec = best
    spheres, zernike, defocus = job.unpack(fitted.q)
    sigma = job.sigmas(fitted, noise)
    n_spheres = 5 * len(spheres)
    beads = job.beads(fitted.q, fitted.converged, noise, rec.optics, config.reconstruction.multislice)
    # each view's uncertainty: the common δ's and, where the rims gave d0_k, theirs
    view_keys = [(ln.row, ln.col) for ln in rec.views.lenslets]
    rims = {} if focus is None or not focus.blurred else dict(zip(focus.keys, focus.sigma_waves))
    defocus_sigma = np.hypot(sigma[-1], [rims.get(k, 0.0) for k in view_keys])
    job.defocus0 = start_defocus(view_keys, None, 1.0, given)  # the given optics' pupil
    before = job.fit(
        job.pack(spheres, zernike0), fixed_dn=bead_dn, hold_pupil=True, steps=steps, should_stop=should_stop
    )
    done = total - 1  # the starts not needed are skipped
    step("the beads under the given pupil")
    result = PupilFit(
        tuple(noll),
        zernike,
        sigma[n_spheres : n_spheres + len(noll)],
        tuple(view_keys),
        defocus,
        defocus_sigma,
        tuple(beads),
        job.residual_over_noise(before.cost, noise),
        job.residual_over_noise(fitted.cost, noise),
        fitted.converged,
    )
    check_pupil_fit(result, bead_ri)
    return result


def check_pupil_fit(fit: PupilFit, bead_ri: float | None) -> None:
    """Refuse a fit that did not converge, leaves the beads unexplained or does not determine its terms.

    Parameters
    ----------
    fit : PupilFit
    bead_ri : float or None
        The beads' index the user gave (a bead left unexplained then may be of another index).

    Raises
    ------
    SsdpcError
        One line that says which.
    """
    if not fit.converged:
        raise SsdpcError(
            "the fit of the pupil to the beads did not converge; nothing written (give a frame with fewer, "
            "isolated beads)"
        )
    unexplained = [b for b in fit.beads if not b.explained]
    if unexplained:
        b = unexplained[0]
        cause = (
            f"beads of another index than --bead-ri {bead_ri}, or an instrument the pupil's terms do not describe"
            if bead_ri is not None
            else "an instrument the pupil's terms do not describe, or objects that are not beads"
        )
        raise SsdpcError(
            f"the fitted pupil leaves {b.residual_over_noise or float('nan'):.1f} x the noise over the bead at "
            f"({b.centre_um[0]:.1f}, {b.centre_um[1]:.1f}, {b.centre_um[2]:.1f}) µm (a bead fits to "
            f"{b.stop_over_noise:.1f}): {cause}; nothing written"
        )
    missing = fit.undetermined()
    if missing:
        raise SsdpcError(
            f"the frame does not determine {', '.join(missing)} (uncertainty over {UNDETERMINED_WAVES} waves); "
            "nothing written: give a frame with more beads spread over the field and in depth"
        )
