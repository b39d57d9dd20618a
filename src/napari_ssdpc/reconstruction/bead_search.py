"""The search behind the bead fit (:mod:`~napari_ssdpc.reconstruction.beads`): the
views of a region with their multislice model as a misfit of spheres, the scan that finds where a
strong bead's misfit has its deepest minimum (the local fit from there:
:mod:`~napari_ssdpc.reconstruction.bead_local_fit`).

A strong bead's misfit has many local minima (each 2π of phase through the bead makes one), so a
local fit from the first-order answer (low in Δn, deep toward the bead's focus) stops in the wrong
one. The scan ranks starts on a coarse model by their misfit: radius x Δn at the candidate's depth,
depth over ± the search range for the best three, radius x Δn again at the best depth.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from napari_ssdpc.reconstruction.memory import available_memory
from napari_ssdpc.reconstruction.sphere_volume import spheres_gradient, spheres_volume

__all__ = [
    "BeadRegion",
    "Stopped",
    "distinct_starts",
    "overlap_groups",
    "scan_starts",
    "wave_neighbours",
]

#: Depth of the full model's planes, µm (a bead's phase is sampled as finely as the simulators do).
FINE_DZ_UM = 0.5
#: The coarse model of the scan: its planes (µm) and its source points (NA units). It keeps the
#: model's lateral sampling: with one sample per view pixel the light a 16 rad bead bends leaves the
#: band, and the coarse misfit ranks a wrong Δn above the true one (docs/beads.md).
COARSE_DZ_UM = 1.0
COARSE = {"source_spacing_na": 0.08}
#: Δn magnitudes of the scan: 0.004 to 0.32 in steps of 1.4 x (a bead's local minima are 2π of
#: phase apart, ≥ 0.1 in Δn for a 5 µm bead: each lies within a step of one of these).
DN_STEPS = 0.004 * 1.4 ** np.arange(14)
#: The fit's bounds: |Δn| at most this (beyond any bead in a microscope), and the radius at least this
#: many model pixels.
DN_LIMIT = 0.6
MIN_RADIUS_PX = 0.5
#: Radii of the scan, in units of the candidate's footprint radius (steps of 1.26 x). The first
#: answer's footprint of a strong bead is no measure of it: 'tv' spread a 1.8 µm bead of 3.9 rad
#: over a footprint of radius 7.5 µm, so the scan reaches down to a fifth of it.
RADIUS_STEPS = tuple(np.geomspace(0.2, 1.6, 10))
#: Radii of the last grid of the scan (at the best depth), in the same units (steps of 1.16 x).
RADIUS_FINE = tuple(np.geomspace(0.2, 1.6, 15))
#: Depth step of the scan, µm.
Z_STEP_UM = 1.5
#: Starts of the scan fitted on the coarse model.
STARTS = 3
#: Coarse fits ranked again on the full model (the better is fitted there).
FINE_STARTS = 2
#: Rounds of scans over the beads of a region that holds several (each scanned with the others held).
ROUNDS = 2
#: Depth offsets of the wave-neighbour scan of beads that share a region, µm.
WAVE_DEPTHS_UM = (-3.0, -1.5, 0.0, 1.5, 3.0)
#: Parameter scales of the fit (x, y, z, R in µm; Δn in hundredths): steps of the same size matter alike.
SCALE = np.array([1.0, 1.0, 1.0, 1.0, 0.01])


class BeadRegion:
    """The views of one region and the multislice model of them on given planes: the misfit of spheres."""

    def __init__(self, measurements, views, roi, z_lo: float, z_hi: float, dz: float, settings, backend):
        self.dz = dz
        self.z_um = np.arange(z_lo, z_hi + dz / 2, dz)
        self.model = measurements.multislice_model(
            self.z_um, dz, roi, settings, backend=backend, max_bytes=available_memory()
        )
        self.y_um, self.x_um = np.asarray(measurements.y_um)[roi[0]], np.asarray(measurements.x_um)[roi[1]]
        bk = self.model.bk
        self.measured = bk.asarray(self.model.crop(views), np.float32)
        self.weight = bk.asarray(self.model.crop(np.asarray(measurements.view_mask, np.float32)))
        self.evaluations = 0

    def covers(self, spheres) -> bool:
        """Every sphere lies inside the model's planes.

        Parameters
        ----------
        spheres : ndarray, (B, 5)
            Rows (x, y, z, R, Δn), µm and dimensionless.

        Returns
        -------
        bool
        """
        top, bottom = self.z_um[0] - self.dz / 2, self.z_um[-1] + self.dz / 2
        return bool(np.all(spheres[:, 2] - spheres[:, 3] >= top) and np.all(spheres[:, 2] + spheres[:, 3] <= bottom))

    def _volume(self, spheres):
        m = self.model
        return spheres_volume(spheres, self.z_um, m.y_um, m.x_um, self.dz)

    def misfit(self, spheres) -> float:
        """½ Σ ‖W (I/I0 − m)‖² of the spheres.

        Parameters
        ----------
        spheres : ndarray, (B, 5)

        Returns
        -------
        float
            (flat-field units)².
        """
        self.evaluations += 1
        r = self.model.views(self._volume(spheres)) - self.measured
        return 0.5 * float(self.model.xp.sum(self.weight * r * r))

    def misfit_and_gradient(self, spheres):
        """The misfit and its gradient with respect to the spheres' parameters.

        Parameters
        ----------
        spheres : ndarray, (B, 5)

        Returns
        -------
        value : float
        grad : ndarray, (B, 5)
        """
        self.evaluations += 1
        value, grad = self.model.misfit(self._volume(spheres), self.measured, self.weight)
        m = self.model
        return value, spheres_gradient(spheres, m.bk.to_host(grad), self.z_um, m.y_um, m.x_um, self.dz)

    def residual_map(self, spheres) -> np.ndarray:
        """The squared residual per view pixel averaged over the views with data.

        Parameters
        ----------
        spheres : ndarray, (B, 5)

        Returns
        -------
        ndarray, (h, w)
            (flat-field units)² on the region's view pixels.
        """
        xp = self.model.xp
        r = self.model.views(self._volume(spheres)) - self.measured
        per = xp.sum(self.weight * r * r, axis=0) / xp.maximum(xp.sum(self.weight, axis=0), 1.0)
        return np.asarray(self.model.bk.to_host(per), float)


class Stopped(Exception):
    """The fit was asked to stop."""


def distinct_starts(found, count: int = 3, exclude=()):
    """The best starts that differ in depth (1 µm), radius or Δn (20 %).

    Parameters
    ----------
    found : list of (float, ndarray (B, 5))
        (misfit, spheres) pairs.
    count : int
    exclude : sequence of ndarray (B, 5)
        Spheres already fitted: starts close to them are left out.

    Returns
    -------
    list of (float, ndarray)
        At most ``count``, best first.
    """
    out: list = []
    for f, p in sorted(found, key=lambda a: a[0]):
        if all(np.abs(p - q).max() > 0 and not _close(p, q) for q in [*exclude, *(q for _, q in out)]):
            out.append((f, p))
        if len(out) == count:
            break
    return out


def _close(p, q) -> bool:
    d = np.abs(p - q)
    return bool(
        np.all(d[:, 2] <= 1.0) and np.all(d[:, 3] <= 0.2 * np.abs(q[:, 3])) and np.all(d[:, 4] <= 0.2 * np.abs(q[:, 4]))
    )


def _within(z, z_range) -> np.ndarray:
    """Which depths lie within ``z_range`` (µm, both ends included)."""
    return (np.asarray(z) >= z_range[0]) & (np.asarray(z) <= z_range[1])


def scan_starts(region: BeadRegion, spheres, b: int, z_search_um: float, sign: float, z_range, dn_steps=DN_STEPS):
    """Starts for sphere ``b`` (the others held): radius x Δn at its depth, depth for the best three,
    radius x Δn again at the best depth on finer radii; every (misfit, spheres) tried.

    Beads of the same phase through their centre (a smaller, denser one beside the true one) are
    separate minima of the misfit: the last grid samples the radius finely enough to start in the
    true one's basin.

    Parameters
    ----------
    region : BeadRegion
        The coarse region, on planes that cover the search.
    spheres : ndarray, (B, 5)
        The current spheres; sphere ``b`` is the one scanned.
    b : int
    z_search_um : float
        Depths tried: ± this around sphere ``b``'s, µm.
    sign : float
        Sign of its Δn.
    z_range : (float, float)
        The depths a centre may take, µm (the volume's first and last plane).
    dn_steps : sequence of float
        The |Δn| tried (:data:`DN_STEPS`; the beads' own when it is known).

    Returns
    -------
    list of (float, ndarray (B, 5))
        Every (misfit, spheres) tried.
    """
    z0, r0 = spheres[b, 2], spheres[b, 3]
    radius_min = region.model.dx

    def at(z, r, dn):
        p = spheres.copy()
        p[b, 2:5] = z, r, dn
        return region.misfit(p), p

    def grid(z, radii):
        return [at(z, max(f * r0, radius_min), sign * d) for f in radii for d in dn_steps]

    found = grid(z0, RADIUS_STEPS)
    depths = z0 + np.arange(-z_search_um, z_search_um + 1e-9, Z_STEP_UM)
    depths = depths[_within(depths, z_range)]
    found += [at(z, p[b, 3], p[b, 4]) for _, p in distinct_starts(found) for z in depths]
    best = min(found, key=lambda a: a[0])[1]
    return found + grid(best[b, 2], RADIUS_FINE)


def wave_neighbours(region: BeadRegion, spheres, sign, wavelength_um: float, z_range, waves=(-1, 0, 1)):
    """Starts one wave of phase away: each sphere's Δn one wave through its centre down, kept or up,
    with its depth moved by :data:`WAVE_DEPTHS_UM`; every combination for two spheres, one sphere at
    a time (the others held) for more.

    Beads on one axis see each other's light: a bead scanned while the other sits in a wrong
    minimum settles in a minimum a wave away (and a little off in depth, where the same phase
    focuses), which a fit of one bead at a time cannot leave. The combinations leave it together.

    Parameters
    ----------
    region : BeadRegion
        The coarse region.
    spheres : ndarray, (B, 5)
        The fitted spheres.
    sign : ndarray, (B,)
        Sign of each sphere's Δn (kept).
    wavelength_um : float
        Vacuum wavelength, µm: a sphere of radius R delays one wave more through its centre per
        λ / 2R of Δn.
    z_range : (float, float)
        The depths a centre may take, µm.
    waves : sequence of int
        The waves of phase each Δn moves by ((0,): Δn known, the depths only).

    Returns
    -------
    list of (float, ndarray (B, 5))
        Every (misfit, spheres) tried that the region covers, the centres within ``z_range``.
    """
    options = []
    for s, sg in zip(spheres, sign, strict=True):
        wave = wavelength_um / (2 * s[3])
        dns = [s[4] + k * wave for k in waves]
        options.append([(s[2] + dz, dn) for dn in dns if 0 < sg * dn <= DN_LIMIT for dz in WAVE_DEPTHS_UM])
    if len(spheres) == 2:
        trials = [np.array(c) for c in itertools.product(*options)]
    else:
        trials = []
        for b, opts in enumerate(options):
            for o in opts:
                t = spheres[:, [2, 4]].copy()
                t[b] = o
                trials.append(t)
    found = []
    for t in trials:
        p = spheres.copy()
        p[:, [2, 4]] = t
        if region.covers(p) and np.all(_within(p[:, 2], z_range)):
            found.append((region.misfit(p), p))
    return found


def overlap_groups(cands, margin_um: float):
    """Candidates whose footprints (plus a margin) come near one another, fitted together.

    Parameters
    ----------
    cands : ndarray, (B, 5)
        Sphere starts (x, y, z, R, Δn).
    margin_um : float
        Footprints closer than this are one group, µm.

    Returns
    -------
    list of list of int
        Indices into ``cands``, one list per group.
    """
    parent = list(range(len(cands)))

    def root(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for i in range(len(cands)):
        for j in range(i):
            if math.dist(cands[i, :2], cands[j, :2]) < cands[i, 3] + cands[j, 3] + margin_um:
                parent[root(i)] = root(j)
    groups: dict = {}
    for i in range(len(cands)):
        groups.setdefault(root(i), []).append(i)
    return list(groups.values())
