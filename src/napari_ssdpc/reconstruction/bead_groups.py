"""The bead fit of one group of candidates after another (:func:`~napari_ssdpc.reconstruction.beads.fit_beads`):
the search of each group (the scans on the coarse model, the coarse fits, the starts one wave of
phase away, the full fit) or, in a series, the full fit from the previous frame's beads; each
fitted sphere reported as a :class:`~napari_ssdpc.reconstruction.bead.Bead` with its checks."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from napari_ssdpc.physics.multislice_source import square_roi
from napari_ssdpc.reconstruction.bead import Bead
from napari_ssdpc.reconstruction.bead_local_fit import local_fit
from napari_ssdpc.reconstruction.bead_search import (
    COARSE,
    COARSE_DZ_UM,
    DN_LIMIT,
    DN_STEPS,
    FINE_DZ_UM,
    FINE_STARTS,
    MIN_RADIUS_PX,
    RADIUS_STEPS,
    ROUNDS,
    STARTS,
    BeadRegion,
    distinct_starts,
    scan_starts,
    wave_neighbours,
)
from napari_ssdpc.reconstruction.fit_objects import explained_limit
from napari_ssdpc.reconstruction.nonlinear import discrepancy_stop
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import MultisliceSettings

__all__ = ["WARM_TOLERANCE", "GroupFit", "report_beads", "stages"]

#: A bead fitted from the previous frame's is kept when its residual is at most this many times
#: the previous one's or its stop, whichever is larger: the model's error, which sets most of the
#: residual of a strong bead, changes little from frame to frame, and a bead one wave of phase
#: off left 2.6 x the residual of the right one (docs/beads.md).
WARM_TOLERANCE = 1.5


@dataclass
class GroupFit:
    """The fit of one group of candidates after another, in one region each (the inputs of
    :func:`~napari_ssdpc.reconstruction.beads.fit_beads`)."""

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
    previous: tuple[Bead, ...] = ()
    #: Every bead's Δn, when known (the fit of the optics to beads of a given index): held, the
    #: search over size and depth only
    delta_n: float | None = None

    def _start(self, label: str) -> None:
        """A stage begins: the progress bar names it, with the stages done so far."""
        if self.progress is not None:
            self.progress(self.done, self.total, label)

    def _step(self, label: str, stages: int = 1) -> None:
        """``stages`` stages done: the progress bar moves on."""
        self.done += stages
        if self.progress is not None:
            self.progress(self.done, self.total, label)

    def _region(self, roi, lo: float, hi: float, dz: float, settings) -> BeadRegion:
        """The views of the region ``roi`` and their model on planes ``lo``..``hi`` every ``dz``, µm."""
        return BeadRegion(self.measurements, self.views, roi, lo, hi, dz, settings, self.backend)

    def _around(self, roi, spheres, dz: float, settings) -> BeadRegion:
        """The region ``roi`` on the planes the spheres fill, 2 µm beyond them."""
        lo, hi = np.min(spheres[:, 2] - spheres[:, 3]) - 2.0, np.max(spheres[:, 2] + spheres[:, 3]) + 2.0
        return self._region(roi, lo, hi, dz, settings)

    def _local(self, roi, start, sign, dz: float, settings, region: BeadRegion | None = None):
        """A local fit on the planes the spheres fill (again on wider ones where one moves out of them);
        ``region``: the first try's, when already built."""
        for attempt in range(3):
            region = region or self._around(roi, start, dz, settings)
            p, value, converged = local_fit(
                region, start, sign, self.iterations, self.z_range, self.should_stop, self.delta_n
            )
            if region.covers(p) or attempt == 2:  # the last region is kept: its views are the ones fitted
                break
            start, region = p, None
        return p, value, converged, region

    def fit(self, cands) -> list[Bead]:
        """The spheres of one group of candidates, fitted together in one region.

        Parameters
        ----------
        cands : ndarray, (B, 5)
            The candidates of the first answer: (x, y, z, footprint radius, Δn), µm.

        Returns
        -------
        list of Bead
            In the order of ``cands`` (or of the previous frame's beads they started from).
        """
        if self.delta_n is not None:
            cands = cands.copy()
            cands[:, 4] = self.delta_n
        sign = np.where(cands[:, 4] < 0, -1.0, 1.0)
        dn_steps = DN_STEPS if self.delta_n is None else (abs(self.delta_n),)
        reach = RADIUS_STEPS[-1] * cands[:, 3]
        x0, x1 = np.min(cands[:, 0] - reach), np.max(cands[:, 0] + reach)
        y0, y1 = np.min(cands[:, 1] - reach), np.max(cands[:, 1] + reach)
        side = max(x1 - x0, y1 - y0) + 2 * self.settings.roi_margin_um
        roi = square_roi(self.measurements.x_um, self.measurements.y_um, ((x0 + x1) / 2, (y0 + y1) / 2), side)
        depth = self.z_search_um + reach.max() + COARSE_DZ_UM
        if self.previous:
            self._start("beads: fitted from the previous frame's")
        warm = self._warm(roi, cands)
        if warm is not None:
            self._step("beads: fitted from the previous frame's", stages(len(cands)))
            return warm
        coarse_settings = self.settings.replace(**COARSE)
        lo = max(cands[:, 2].min() - depth, self.z_range[0] - reach.max() - COARSE_DZ_UM)
        hi = min(cands[:, 2].max() + depth, self.z_range[1] + reach.max() + COARSE_DZ_UM)
        coarse = self._region(roi, lo, hi, COARSE_DZ_UM, coarse_settings)
        spheres = cands.copy()

        # beads that share a region are scanned one at a time with the others held; a second round
        # scans each again with the others where the first round put them
        order = [b for _ in range(1 if len(spheres) == 1 else ROUNDS) for b in range(len(spheres))]
        for b in order:
            self._start("beads: scanning depth, size and index")
            found = scan_starts(coarse, spheres, b, self.z_search_um, sign[b], self.z_range, dn_steps)
            self._step("beads: scanning depth, size and index")
            self._start("beads: coarse fit")
            fits = [self._local(roi, p, sign, COARSE_DZ_UM, coarse_settings) for _, p in distinct_starts(found, STARTS)]
            fits.sort(key=lambda a: a[1])
            spheres = fits[0][0]
            self._step("beads: coarse fit")
        if len(spheres) > 1:
            # beads on one axis: the minima one wave of phase away, moved together
            self._start("beads: one wave of phase away")
            waves = (-1, 0, 1) if self.delta_n is None else (0,)
            found = wave_neighbours(coarse, spheres, sign, self.optics.wavelength_um, self.z_range, waves)
            starts = distinct_starts(found, STARTS, exclude=[f[0] for f in fits])
            fits += [self._local(roi, p, sign, COARSE_DZ_UM, coarse_settings) for _, p in starts]
            fits.sort(key=lambda a: a[1])
            self._step("beads: one wave of phase away")
        # the coarse model's error can rank the minimum one 2π of phase away first: the best two are
        # ranked again on the full model (one pass each), and the better is fitted there
        self._start("beads: full fit")
        last = distinct_starts([(f[1], f[0]) for f in fits], FINE_STARTS)
        ranked = [(self._around(roi, p, FINE_DZ_UM, self.settings), p) for _, p in last]
        region, best = min(ranked, key=lambda a: a[0].misfit(a[1]))
        spheres, _, converged, fine = self._local(roi, best, sign, FINE_DZ_UM, self.settings, region)
        self._step("beads: full fit")
        return report_beads(fine, spheres, converged, self.noise, self.optics, self.settings)

    def _warm(self, roi, cands) -> list[Bead] | None:
        """The group fitted on the full model from the previous frame's beads, without the scan.

        Every previous bead of a candidate's sign whose centre lies within its footprint is a start (a
        lone candidate on a lone bead gives it its centre in x and y: the first answer has a bead's
        lateral centre right, not its depth); the candidates must each have at least one.

        Returns
        -------
        list of Bead or None
            None when a candidate has no previous bead (an object new to the frame) or when the
            fit does not keep every bead explained and its residual within :data:`WARM_TOLERANCE`
            of the previous one's or of its stop (it may have settled in another minimum): the
            group is then searched.
        """
        near = [
            [
                b for b in self.previous
                if math.hypot(b.centre_um[0] - c[0], b.centre_um[1] - c[1]) <= c[3] and b.delta_n * c[4] > 0
            ]
            for c in cands
        ]  # fmt: skip
        if not self.previous or not all(near):
            return None
        prev = list({id(b): b for found in near for b in found}.values())
        start = np.array([[*b.centre_um, b.diameter_um / 2, b.delta_n] for b in prev])
        if len(cands) == 1 and len(prev) == 1:
            start[0, :2] = cands[0, :2]
        sign = np.sign(start[:, 4])
        spheres, _, converged, fine = self._local(roi, start, sign, FINE_DZ_UM, self.settings)
        beads = report_beads(fine, spheres, converged, self.noise, self.optics, self.settings)
        bound = [WARM_TOLERANCE * max(b.stop_over_noise, p.residual_over_noise or 0.0) for b, p in zip(beads, prev)]
        kept = all(not b.note and (b.residual_over_noise or math.inf) <= r for b, r in zip(beads, bound, strict=True))
        return beads if kept else None


def stages(beads: int) -> int:
    """The progress stages of the search of a group of beads.

    Parameters
    ----------
    beads : int
        The group's beads.

    Returns
    -------
    int
        The scans and coarse fits (each bead once, or ``ROUNDS`` times when several share the
        region), the starts one wave away when several do, and the full fit.
    """
    return 2 * beads * (1 if beads == 1 else ROUNDS) + (1 if beads == 1 else 2)


def report_beads(region: BeadRegion, spheres, converged: bool, noise: float, optics, settings) -> list[Bead]:
    """Each sphere as a Bead, with the residual of the views over its footprint and its checks.

    Parameters
    ----------
    region : BeadRegion
        The region and model the spheres were fitted on.
    spheres : ndarray, (B, 5)
        (x, y, z, R, Δn), µm.
    converged : bool
        The fit ended on its convergence test.
    noise : float
        The views' noise σ.
    optics : Optics
        The medium's index and the objective's NA (a bead's footprint in the most oblique view).
    settings : MultisliceSettings
        The model's share of the stop.

    Returns
    -------
    list of Bead
    """
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
