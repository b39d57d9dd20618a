"""Beads measured as beads: every bead of a frame fitted as a sphere (centre, diameter, RI) with the
multislice model of the views.

Microscopists check an instrument with beads of known size and index. A voxel reconstruction of a
strong bead is biased (the first-order 'tv' loses mass and moves it toward the bead's focus); a
sphere has five numbers, and the multislice model of the views
(:class:`~napari_ssdpc.physics.views_multislice.ViewsMultislice`) predicts its views without the
first-order approximation. Here each bead is the sphere (x, y, z, R, Δn) that minimises

    ½ Σ_k ‖W (I_k(spheres) / I0_k − m_k)‖²

(the views' misfit of the multislice fit, with Δn of the voxels from
:mod:`~napari_ssdpc.reconstruction.sphere_volume`), by L-BFGS-B on the gradient the model's adjoint
gives. The misfit of a strong bead has many local minima (each 2π of phase through the bead is one),
so the fit starts from the best of a scan:

1. the candidates are the objects of a first answer (the 'tv' volume): their centre and the radius of
   their footprint;
2. on a coarse model (a source point every 0.08 NA instead of 0.03, 1 µm planes), a scan of radius
   x Δn at the candidate's depth, of depth over ± ``z_search_um`` for the best three, and of radius x
   Δn again at the best depth; the three best distinct starts are fitted on the coarse model;
3. the best two of those are ranked again by their misfit on the full model (the multislice
   settings' sampling, 0.5 µm planes), and the better is fitted there.

Beads whose footprints come near one another are fitted together in one region (their spheres add):
each is scanned with the others held, twice over, and then the starts one wave of phase away for all
of them at once (each Δn one wave through the centre down, kept or up, each depth moved by up to
3 µm) are ranked and the best fitted: a bead on the axis of another sees its light and can settle a
wave away while the other is wrong.
A bead is reported with the residual of the views over its footprint over the noise, and flagged when
the fit did not converge or the model does not explain the views there.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from napari_ssdpc.errors import Cancelled, SsdpcError
from napari_ssdpc.physics.multislice_source import square_roi
from napari_ssdpc.reconstruction.bead_search import (
    COARSE,
    COARSE_DZ_UM,
    DN_LIMIT,
    FINE_DZ_UM,
    FINE_STARTS,
    MIN_RADIUS_PX,
    RADIUS_STEPS,
    ROUNDS,
    STARTS,
    BeadRegion,
    Stopped,
    distinct_starts,
    local_fit,
    overlap_groups,
    scan_starts,
    wave_neighbours,
)
from napari_ssdpc.reconstruction.dpc import phase_to_delta_n
from napari_ssdpc.reconstruction.fit_objects import around_bead, bead_candidates, explained_limit, voxel_steps
from napari_ssdpc.reconstruction.nonlinear import discrepancy_stop
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import MultisliceSettings

__all__ = ["Bead", "fit_beads", "measure_beads"]


@dataclass(frozen=True)
class Bead:
    """One fitted bead.

    Attributes
    ----------
    centre_um : tuple of float
        (x, y, z), µm (z > 0: farther from the objective).
    diameter_um : float
    ri : float
        Its refractive index (the medium's plus Δn).
    delta_n : float
        Its index minus the medium's.
    residual_over_noise : float or None
        Mean squared residual of the views over its footprint, in noise variances.
    stop_over_noise : float
        The residual the model reaches on a well-explained bead (the noise and the model's error).
    converged : bool
        The fit ended on its convergence test.
    explained : bool
        The residual is within twice the stop.
    note : str
        What a user must know before trusting it ('' when nothing): not converged, not explained,
        overlapping another bead.
    first_answer_ratio : float or None
        The voxel answer the beads were found in (e.g. 'tv'), checked against the sphere: its
        integrated Δn around the bead
        (:func:`~napari_ssdpc.reconstruction.fit_objects.around_bead`) over the sphere's volume x Δn.
    """

    centre_um: tuple[float, float, float]
    diameter_um: float
    ri: float
    delta_n: float
    residual_over_noise: float | None
    stop_over_noise: float
    converged: bool
    explained: bool
    note: str = ""
    first_answer_ratio: float | None = None

    def to_dict(self) -> dict:
        """Plain numbers for JSON."""
        return asdict(self)


def fit_beads(
    measurements,
    views,
    dn,
    z_um,
    *,
    noise: float,
    optics,
    settings,
    z_search_um: float = 12.0,
    min_fraction: float = 0.05,
    iterations: int = 60,
    backend=None,
    progress=None,
    should_stop=None,
) -> list[Bead]:
    """Every bead of a frame fitted as a sphere with the multislice model of its views.

    Parameters
    ----------
    measurements : Measurements
        The views' front end (its grid, masks and multislice model).
    views : ndarray, (K, ny, nx)
        The flat-fielded views of the frame.
    dn : ndarray, (Z, ny, nx)
        A first answer for the frame (the 'tv' volume): where the beads are.
    z_um : ndarray, (Z,)
        Its planes, µm.
    noise : float
        The views' noise σ, flat-field units (the 'tv' report's ``tv_noise``).
    optics : Optics
        The medium's index (RI = medium + Δn) and the objective's NA (a bead's footprint in the views).
    settings : MultisliceSettings
        The multislice model's sampling and its stop (the residual a well-explained bead reaches).
    z_search_um : float
        How far above and below the first answer's depth a bead is looked for, µm (a strong
        bead's first-order answer lies toward its focus); a bead's centre stays within the planes
        ``z_um`` (the volume the user gave holds the sample; a sphere start beyond it could not be
        drawn).
    min_fraction : float
        Objects of the first answer with less integrated |Δn| than this fraction of the largest's are
        not taken for beads.
    iterations : int
        Most L-BFGS iterations of each fit.
    backend : {'cpu', 'gpu'} or Backend, optional
    progress : callable, optional
        ``progress(done, total, label)`` after each stage (the scan, the coarse fit of every bead; the
        starts one wave away and the full fit of every group).
    should_stop : callable, optional
        Checked at every evaluation; True stops with :class:`~napari_ssdpc.errors.Cancelled`.

    Returns
    -------
    list of Bead
        Largest first.
    """
    if not (noise > 0 and math.isfinite(noise)):
        raise SsdpcError(f"the views' noise must be a positive number to judge a bead's fit, got {noise}")
    cands = bead_candidates(dn, z_um, measurements.y_um, measurements.x_um)
    if len(cands):
        size = np.abs(cands[:, 4]) * cands[:, 3] ** 3
        cands = cands[size >= min_fraction * size.max()]
    groups = overlap_groups(cands, settings.roi_margin_um)
    total = sum(2 * len(g) * (1 if len(g) == 1 else ROUNDS) + (1 if len(g) == 1 else 2) for g in groups)
    job = _GroupFit(
        measurements,
        views,
        noise,
        optics,
        settings,
        z_search_um,
        (float(np.min(z_um)), float(np.max(z_um))),
        iterations,
        backend,
        should_stop,
        progress,
        total,
    )
    out: list[Bead] = []
    try:
        for g in groups:
            out += job.fit(cands[g])
    except Stopped:
        raise Cancelled("the bead fit was stopped") from None
    voxel = float(np.prod(voxel_steps(z_um, measurements.y_um, measurements.x_um)))
    out = [
        replace(
            b,
            first_answer_ratio=float(np.sum(dn[around_bead(b, z_um, measurements.y_um, measurements.x_um)]))
            * voxel
            / (math.pi / 6 * b.diameter_um**3 * b.delta_n),
        )
        for b in out
    ]
    return sorted(out, key=lambda b: -(b.diameter_um**3) * abs(b.delta_n))


@dataclass
class _GroupFit:
    """The fit of one group of candidates after another, in one region each (the inputs of
    :func:`fit_beads`)."""

    measurements: Any
    views: np.ndarray
    noise: float
    optics: Optics
    settings: MultisliceSettings
    z_search_um: float
    z_range: tuple[float, float]
    iterations: int
    backend: Any
    should_stop: Callable[[], bool] | None
    progress: Callable[[int, int, str], None] | None = None
    total: int = 0
    done: int = 0

    def step(self, label: str) -> None:
        """One stage done: the progress bar moves on."""
        self.done += 1
        if self.progress is not None:
            self.progress(self.done, self.total, label)

    def region(self, roi, lo: float, hi: float, dz: float, settings) -> BeadRegion:
        """The views of the region ``roi`` and their model on planes ``lo``..``hi`` every ``dz``, µm."""
        return BeadRegion(self.measurements, self.views, roi, lo, hi, dz, settings, self.backend)

    def around(self, roi, spheres, dz: float, settings) -> BeadRegion:
        """The region ``roi`` on the planes the spheres fill, 2 µm beyond them."""
        lo, hi = np.min(spheres[:, 2] - spheres[:, 3]) - 2.0, np.max(spheres[:, 2] + spheres[:, 3]) + 2.0
        return self.region(roi, lo, hi, dz, settings)

    def local(self, roi, start, sign, dz: float, settings, region: BeadRegion | None = None):
        """A local fit on the planes the spheres fill (again on wider ones where one moves out of them);
        ``region``: the first try's, when already built."""
        for _ in range(3):
            region = region or self.around(roi, start, dz, settings)
            p, value, converged = local_fit(region, start, sign, self.iterations, self.z_range, self.should_stop)
            if region.covers(p):
                break
            start, region = p, None
        return p, value, converged, region

    def fit(self, cands) -> list[Bead]:
        """The spheres of one group of candidates, fitted together in one region."""
        sign = np.where(cands[:, 4] < 0, -1.0, 1.0)
        reach = RADIUS_STEPS[-1] * cands[:, 3]
        x0, x1 = np.min(cands[:, 0] - reach), np.max(cands[:, 0] + reach)
        y0, y1 = np.min(cands[:, 1] - reach), np.max(cands[:, 1] + reach)
        side = max(x1 - x0, y1 - y0) + 2 * self.settings.roi_margin_um
        roi = square_roi(self.measurements.x_um, self.measurements.y_um, ((x0 + x1) / 2, (y0 + y1) / 2), side)
        depth = self.z_search_um + reach.max() + COARSE_DZ_UM
        coarse_settings = self.settings.replace(**COARSE)
        lo = max(cands[:, 2].min() - depth, self.z_range[0] - reach.max() - COARSE_DZ_UM)
        hi = min(cands[:, 2].max() + depth, self.z_range[1] + reach.max() + COARSE_DZ_UM)
        coarse = self.region(roi, lo, hi, COARSE_DZ_UM, coarse_settings)
        spheres = cands.copy()

        # beads that share a region are scanned one at a time with the others held; a second round
        # scans each again with the others where the first round put them
        order = [b for _ in range(1 if len(spheres) == 1 else ROUNDS) for b in range(len(spheres))]
        for b in order:
            found = scan_starts(coarse, spheres, b, self.z_search_um, sign[b], self.z_range)
            self.step("beads: scanning depth, size and index")
            fits = [self.local(roi, p, sign, COARSE_DZ_UM, coarse_settings) for _, p in distinct_starts(found, STARTS)]
            fits.sort(key=lambda a: a[1])
            spheres = fits[0][0]
            self.step("beads: coarse fit")
        if len(spheres) > 1:
            # beads on one axis: the minima one wave of phase away, moved together
            found = wave_neighbours(coarse, spheres, sign, self.optics.wavelength_um, self.z_range)
            starts = distinct_starts(found, STARTS, exclude=[f[0] for f in fits])
            fits += [self.local(roi, p, sign, COARSE_DZ_UM, coarse_settings) for _, p in starts]
            fits.sort(key=lambda a: a[1])
            self.step("beads: one wave of phase away")
        # the coarse model's error can rank the minimum one 2π of phase away first: the best two are
        # ranked again on the full model (one pass each), and the better is fitted there
        last = distinct_starts([(f[1], f[0]) for f in fits], FINE_STARTS)
        ranked = [(self.around(roi, p, FINE_DZ_UM, self.settings), p) for _, p in last]
        region, best = min(ranked, key=lambda a: a[0].misfit(a[1]))
        spheres, _, converged, fine = self.local(roi, best, sign, FINE_DZ_UM, self.settings, region)
        self.step("beads: full fit")
        return _report(fine, spheres, converged, self.noise, self.optics, self.settings)


def _report(region: BeadRegion, spheres, converged: bool, noise: float, optics, settings) -> list[Bead]:
    """Each sphere as a Bead, with the residual of the views over its footprint."""
    per_pixel = region.residual_map(spheres)
    m = region.model
    xp = m.xp
    contrast_map = np.asarray(
        m.bk.to_host(
            xp.sum(region.weight * (region.measured - 1.0) ** 2, axis=0)
            / xp.maximum(xp.sum(region.weight, axis=0), 1.0)
        ),
        float,
    )
    tilt = optics.na / math.sqrt(optics.medium_index**2 - optics.na**2)
    beads = []
    for i, s in enumerate(spheres):
        x, y, z, r, dn = (float(v) for v in s)
        reach = r + 1.0 + abs(z) * tilt  # the bead's image in the most oblique view
        foot = np.hypot(region.x_um[None, :] - x, region.y_um[:, None] - y) <= reach
        ratio = float(per_pixel[foot].mean()) / noise**2 if foot.any() else None
        stop = discrepancy_stop(settings, float(contrast_map[foot].mean()), noise)
        explained = ratio is not None and ratio <= explained_limit(stop)
        notes = [] if converged else ["the fit did not converge"]
        if abs(dn) >= 0.99 * DN_LIMIT or r <= 1.01 * MIN_RADIUS_PX * m.dx:
            notes.append("the fit ended on a bound of its Δn or radius (no bead of this frame fits as a sphere)")
        if not explained:
            notes.append(
                f"the model leaves {ratio or float('nan'):.1f} x the noise over it (a bead fits to {stop:.1f})"
            )
        notes += [
            f"overlaps the bead at ({o[0]:.1f}, {o[1]:.1f}, {o[2]:.1f}) µm"
            for j, o in enumerate(spheres)
            if j != i and math.dist(o[:3], s[:3]) < o[3] + s[3]
        ]
        beads.append(
            Bead((x, y, z), 2 * r, optics.medium_index + dn, dn, ratio, stop, converged, explained, "; ".join(notes))
        )
    return beads


def measure_beads(
    rec, frame, *, result=None, name: str = "frame", progress=None, should_stop=None, **options
) -> list[Bead]:
    """The beads of a raw frame, each fitted as a sphere (the Python API of ``ssdpc beads``).

    Parameters
    ----------
    rec : Reconstructor
        Built for the frame's calibration and flat with the 'tv' method (or its 'multislice'
        refinement): its 'tv' answer says where the beads are.
    frame : array_like, (H, W)
        The raw frame, camera units.
    result : Result, optional
        The 'tv' result of this frame when it is already computed (not solved again).
    name : str
        The frame's name in error messages.
    progress, should_stop
        As :func:`fit_beads`; ``progress`` also follows the 'tv' solve.
    **options
        ``z_search_um``, ``min_fraction``, ``iterations``: see :func:`fit_beads`.

    Returns
    -------
    list of Bead
        Largest first; empty when the frame holds no object.
    """
    views, _ = rec.views.measure(frame, name)
    if result is None:
        tv = rec.method if rec.method.start is None else rec.method.start
        if tv.name != "tv":
            raise SsdpcError(f"the bead fit starts from the 'tv' answer; the reconstructor solves with '{tv.name}'")
        sol = tv.solve(views, progress=progress, should_stop=should_stop)
        dn, noise = phase_to_delta_n(sol.phase, rec.optics.wavelength_um, rec.dz), sol.report.get("tv_noise")
    else:
        dn, noise = result.delta_n, result.settings.get("tv_noise")
    if noise is None:
        raise SsdpcError("the result holds no 'tv' noise estimate: give a result of the 'tv' method, or none")
    settings = rec.config.reconstruction
    return fit_beads(
        rec.views,
        views,
        dn,
        rec.z_um,
        noise=float(noise),
        optics=rec.optics,
        settings=settings.multislice,
        backend=rec.backend,
        progress=progress,
        should_stop=should_stop,
        **options,
    )
