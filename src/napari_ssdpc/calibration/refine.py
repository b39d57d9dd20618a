"""Calibration step 2: every EI's own centre, and the lattice through the centres to trust.

Once a first lattice labels the detected disks, each cell's rim is measured again away from
its neighbours (``all_rims``), fitted to sub-pixel precision (``refine_centres``), EIs whose rim
a brighter neighbour pulls are set aside (``outshone``), and an affine lattice is fitted
through the rest with outliers dropped (``fit_lattice``; with few EIs, by leaving one out).
"""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.calibration.axis import all_cells, ei_brightness
from napari_ssdpc.calibration.disks import fit_rim, rim_circle
from napari_ssdpc.calibration.lattice_fit import MIN_AFFINE, MIN_EIS, AffineLattice, fit_affine
from napari_ssdpc.statistics import robust_sigma

__all__ = ["OUTLIER", "SMALL_EI_PX", "all_rims", "fit_lattice", "outshone", "refine_centres"]

OUTLIER = 0.08  # a rim fit more than 8 % of the pitch off the lattice is not trusted
#: With few EIs, a centre the others predict worse than this fraction of the pitch (and 4 x worse
#: than the rest) is dropped: one pulled rim would otherwise move the whole lattice.
LOO_OUTLIER = 0.005
#: A small array's white frame (every lenslet in the pupil lit) fixes an affine lattice from this many EIs.
MIN_AFFINE_LIT = 6
DIM_EDGE = 0.25  # EIs with a rim less steep than this x the median take their lattice position

_OFFSETS = np.array([(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)], float)


def all_rims(img, lat: AffineLattice, circles, n_idx):
    """Rim circles of every lattice cell in the frame, measured again away from the
    neighbours' touching zones (the lattice now says where they are); cells the detection
    missed (dim EIs at the pupil edge) count when their rim is at least 5 % as steep
    as the median rim. Returns the circles, their indices (K, 2) and whether each rim is
    at least a quarter as steep as the median (bright enough to place its EI on its own).

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, dark level removed.
    lat : AffineLattice
        The first lattice.
    circles : list of Circle
        The detected disks' circles.
    n_idx : ndarray, (K, 2)
        Their lattice indices.

    Returns
    -------
    circles : list of Circle
    indices : ndarray, (K', 2)
    bright : ndarray, bool, (K',)
    """
    r_med = float(np.median([c.radius for c in circles]))
    edge_med = float(np.median([c.edge for c in circles]))
    found = {tuple(int(v) for v in n): c for c, n in zip(circles, n_idx)}
    cells = np.rint(lat.index(all_cells(lat, img.shape))).astype(int)
    out, idx = [], []
    for n in cells:
        key = (int(n[0]), int(n[1]))
        guess = found[key].centre if key in found else lat.centres(n)
        c = rim_circle(img, guess, r_med, neighbours=lat.centres(n + _OFFSETS))
        if c is None and key in found:
            c = found[key]
        if (
            c is None
            or c.inlier_frac < 0.4
            or c.edge < 0.05 * edge_med
            or abs(c.radius / r_med - 1) > 0.2
            or math.hypot(*(c.centre - lat.centres(n))) > 0.15 * lat.pitch
        ):
            continue
        out.append(c)
        idx.append(n)
    bright = np.array([c.edge >= DIM_EDGE * edge_med for c in out], bool)
    return out, np.array(idx, float).reshape(-1, 2), bright


def refine_centres(img, lat: AffineLattice, circles, n_idx, dark):
    """Sub-pixel rim fit of every EI; falls back to its robust circle.

    Returns centres (K, 2), σ (K,), radii (K,) and whether the rim fit held (K,).

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, dark level removed.
    lat : AffineLattice
    circles : list of Circle
    n_idx : ndarray, (K, 2)
        Lattice indices of the circles.
    dark : float
        Level outside the EIs.

    Returns
    -------
    centres : ndarray, (K, 2)
        (x, y), px.
    sigma : ndarray, (K,)
        Standard errors, px.
    radii : ndarray, (K,)
        px.
    held : ndarray, bool, (K,)
    """
    r_med = float(np.median([c.radius for c in circles]))
    first = [
        fit_rim(img, c, lat.centres(n + _OFFSETS), float(np.clip(0.25 * r_med, 2, 12)), dark)
        for c, n in zip(circles[:12], n_idx[:12])
    ]
    widths = [f.width for f in first if f is not None]
    delta = float(np.clip(5 * np.median(widths) + 2, 2, 0.3 * r_med)) if widths else float(np.clip(0.2 * r_med, 2, 12))
    xy, sig, rad, held = [], [], [], []
    for c, n in zip(circles, n_idx):
        f = fit_rim(img, c, lat.centres(n + _OFFSETS), delta, dark)
        held.append(f is not None and math.hypot(*(f.centre - c.centre)) < max(0.5, 0.05 * c.radius))
        if f is not None and held[-1]:
            xy.append(f.centre)
            sig.append(f.sigma)
            rad.append(f.radius)
        else:
            xy.append(c.centre)
            sig.append(c.rms / math.sqrt(max(c.inliers.sum(), 1) / 2))
            rad.append(c.radius)
    return np.array(xy), np.array(sig), np.array(rad), np.array(held, bool)


#: Below this EI radius (px) a rim fit is not trusted on its own, and an EI beside a dimmer one is set
#: aside. Measured on white frames with per-lenslet offsets of 2 % of the pitch: from a radius of
#: 7.5 px (15 px pitch) the rim fits place every EI within 0.04 px, the lattice alone 0.3-0.6 px.
SMALL_EI_PX = 5.0


def outshone(img, xy, n, radius):
    """EIs whose rim a neighbour's skirt pulls, so that the lattice places them better:
    those dimmer than 0.85 x their brightest neighbour (the edge of the pupil) and, for
    small EIs (radius under ``SMALL_EI_PX``), also those with a neighbour dimmer than 0.85 x
    themselves (the outer ring of lit EIs).

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, dark level removed.
    xy : ndarray, (K, 2)
        EI centres (x, y), px.
    n : ndarray, (K, 2)
        Lattice indices.
    radius : float
        EI radius, px.

    Returns
    -------
    ndarray, bool, (K,)
    """
    b = ei_brightness(img, xy, radius, 0.5)
    level = {tuple(int(v) for v in k): float(v) for k, v in zip(n, b)}
    out = np.zeros(len(xy), bool)
    for i, k in enumerate(n):
        nb = np.array(
            [level.get((int(k[0]) + dx, int(k[1]) + dy), 0.0) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
        )
        out[i] = bool(b[i] < 0.85 * nb.max()) or (radius < SMALL_EI_PX and bool(nb.min() < 0.85 * b[i]))
    return out


def fit_lattice(xy, n, sig, pitch, flip, usable, cell, whole_array=False):
    """Affine lattice through the usable measured centres (weights 1/σ²), without outliers.

    Returns the lattice, the residuals (K, 2) and a mask of the trusted centres.

    Parameters
    ----------
    xy : ndarray, (K, 2)
        Centres (x, y), px.
    n : ndarray, (K, 2)
        Lattice indices.
    sig : ndarray, (K,)
        Standard errors, px.
    pitch : float
        px.
    flip : ndarray, (2, 2)
        diag(±1, ±1) of the camera's mirroring.
    usable : ndarray, bool, (K,)
        Centres that may fix the lattice.
    cell : ndarray, (2, 2)
        Unit cell in pitches.
    whole_array : bool
        Every lenslet in the pupil is lit (a white frame of a small array): from
        ``MIN_AFFINE_LIT`` centres the lattice is affine (its shear is measured), and no centre
        is left out for disagreeing with few others (a real array's own scatter).

    Returns
    -------
    lattice : AffineLattice
    residuals : ndarray, (K, 2)
        px.
    trusted : ndarray, bool, (K,)
    """
    min_affine = MIN_AFFINE_LIT if whole_array else MIN_AFFINE
    w = 1.0 / np.maximum(sig, 2e-4 * pitch) ** 2
    trusted = usable.copy() if usable.sum() >= MIN_EIS else np.ones(len(xy), bool)

    def fit(trusted):
        lat, _ = fit_affine(xy[trusted], n[trusted], flip, w[trusted], cell, min_affine)
        return lat, xy - lat.centres(n)

    lat, res = fit(trusted)
    for _ in range(3):
        rr = np.hypot(res[:, 0], res[:, 1])
        new = trusted & (rr < max(OUTLIER * pitch, 5 * robust_sigma(rr[trusted], about=0.0)))
        if new.sum() < MIN_EIS or np.array_equal(new, trusted):
            break
        trusted = new
        lat, res = fit(trusted)
    if MIN_EIS < trusted.sum() < MIN_AFFINE and not whole_array:
        trusted = leave_one_out(xy, n, w, flip, cell, trusted, pitch)
        lat, res = fit(trusted)
    return lat, res, trusted


def leave_one_out(xy, n, w, flip, cell, trusted, pitch):
    """Few EIs fix a similarity lattice with little redundancy, so a median test cannot see one
    pulled rim. Fit without each centre in turn; where leaving one out makes the others agree
    (their scatter, per degree of freedom) and the others predict it worse than ``LOO_OUTLIER``
    of the pitch and 4 x that scatter, drop it, and look again.

    Parameters
    ----------
    xy : ndarray, (K, 2)
        Centres (x, y), px.
    n : ndarray, (K, 2)
        Lattice indices.
    w : ndarray, (K,)
        Weights 1/σ².
    flip : ndarray, (2, 2)
    cell : ndarray, (2, 2)
    trusted : ndarray, bool, (K,)
        The centres trusted so far.
    pitch : float
        px.

    Returns
    -------
    ndarray, bool, (K,)
        The centres still trusted.
    """
    idx = np.flatnonzero(trusted)
    while len(idx) > MIN_EIS:
        err, scatter = np.empty(len(idx)), np.empty(len(idx))
        for j, i in enumerate(idx):
            rest = np.delete(idx, j)
            lat, res = fit_affine(xy[rest], n[rest], flip, w[rest], cell)
            err[j] = float(np.hypot(*(xy[i] - lat.centres(n[i : i + 1])[0])))
            scatter[j] = float(np.sqrt(np.sum(res**2) / max(2 * len(rest) - 4, 1)))
        best = int(np.argmin(scatter))
        if err[best] < max(LOO_OUTLIER * pitch, 4 * scatter[best]):
            break
        idx = np.delete(idx, best)
    out = np.zeros(len(xy), bool)
    out[idx] = True
    return out
