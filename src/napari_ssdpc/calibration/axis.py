"""The optical axis and the kind of frame, from the brightness of the EIs.

The MLA sits in a plane conjugate to the objective's back focal plane (paper §2,
Fig. 1), so the objective pupil appears on the MLA as a disk of radius
``f_obj NA m_r`` and each EI's brightness is proportional to the part of its lenslet
inside that disk. On a white frame (condenser fully open, σ = 1) the axis is fitted so
that EI brightness = offset + scale x (smooth illumination envelope: tilt and radial
quadratic about the axis) x ``circle_overlap_fraction(|a_k|, r_ml, pupil_radius_mla_um)``.
On a flat or sample frame (σ < 1) only the lenslets that see the condenser disk are
lit; the same fit with the source radius ``σ x pupil radius`` gives the axis.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage, optimize

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.settings.lenslets import circle_overlap_fraction


def ei_brightness(img, centres, radius, inner=0.5):
    """Mean of each EI inside ``inner`` x R (NaN where the disk leaves the frame).

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, camera units, dark level removed.
    centres : ndarray, (K, 2)
        EI centres (x, y), px.
    radius : float
        EI radius R, px.
    inner : float
        Fraction of R averaged over.

    Returns
    -------
    ndarray, float64, (K,)
    """
    r = inner * radius
    oy, ox = np.mgrid[-int(r) : int(r) + 1, -int(r) : int(r) + 1]
    inside = ox**2 + oy**2 <= r * r
    ox, oy = ox[inside].astype(float), oy[inside].astype(float)
    H, W = img.shape
    out = np.full(len(centres), np.nan)
    for k, (cx, cy) in enumerate(centres):
        if cx - r < 0 or cy - r < 0 or cx + r > W - 1 or cy + r > H - 1:
            continue
        out[k] = ndimage.map_coordinates(img, [cy + oy, cx + ox], order=1).mean()
    return out


def all_cells(lat, shape):
    """Centres of every lattice cell whose centre lies in the frame.

    Parameters
    ----------
    lat : AffineLattice
    shape : (int, int)
        Frame shape (H, W).

    Returns
    -------
    ndarray, (K, 2)
        Cell centres (x, y), px.
    """
    H, W = shape
    corners = np.array([[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1]], float)
    ij = lat.index(corners)
    lo, hi = np.floor(ij.min(0)) - 1, np.ceil(ij.max(0)) + 1
    cc, rr = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
    n = np.stack([cc.ravel(), rr.ravel()], 1)
    xy = lat.centres(n)
    ok = (xy[:, 0] >= -0.5) & (xy[:, 0] <= W - 0.5) & (xy[:, 1] >= -0.5) & (xy[:, 1] <= H - 0.5)
    return xy[ok]


def fit_axis(xy, b, radius_um, um_per_px, optics, tilt):
    """Axis (x, y) px from EI brightness b_k = c0 + s g_k f(|a_k|): f is the part of the
    lenslet inside the disk of ``radius_um`` on the MLA (objective pupil or condenser
    disk), g_k = 1 + g_x X + g_y Y + g_2 (X² + Y²) a smooth illumination envelope about
    the axis (``tilt``; X, Y in units of the pupil radius). Returns axis, rms/s,
    σ_axis and the parameters.

    Parameters
    ----------
    xy : ndarray, (K, 2)
        EI centres (x, y), px.
    b : ndarray, (K,)
        EI brightness, camera units.
    radius_um : float
        Radius of the disk that lights the lenslets, µm on the MLA.
    um_per_px : float
        MLA µm per sensor pixel.
    optics : Optics
    tilt : bool
        Fit the illumination envelope g_k too.

    Returns
    -------
    axis : ndarray, (2,)
        (x, y), px.
    rms : float
        Residual rms over s.
    sigma : float
        Standard error of the axis, px.
    params : ndarray
        All fitted parameters.
    """
    ok = np.isfinite(b)
    xy, b = xy[ok], b[ok]
    r_ml = optics.lenslet_radius_um
    c_guess = float(np.percentile(b, 10))
    if c_guess > 0.5 * float(b.max()):  # nearly every EI lit (the pupil fills the sensor)
        c_guess = float(b.min())
    wt = np.clip(b - c_guess, 0, None)
    axis0 = (xy * wt[:, None]).sum(0) / wt.sum()
    near = np.hypot(*(xy - axis0).T) * um_per_px < radius_um + r_ml + 1.5 * optics.pitch_um
    xy, b = xy[near], b[near]
    span = (radius_um + r_ml) / um_per_px

    def model(p):
        d = np.hypot(xy[:, 0] - p[0], xy[:, 1] - p[1]) * um_per_px
        f = circle_overlap_fraction(d, r_ml, radius_um)
        g = 1.0
        if tilt:
            X, Y = (xy[:, 0] - p[0]) / span, (xy[:, 1] - p[1]) / span
            g = 1.0 + p[4] * X + p[5] * Y + p[6] * (X * X + Y * Y)
        return p[3] + p[2] * g * f

    s0 = float(b.max() - c_guess)
    p0 = [axis0[0], axis0[1], s0, c_guess] + ([0.0, 0.0, 0.0] if tilt else [])
    if len(b) <= len(p0):
        raise SsdpcError(
            "too few elemental images around the optical axis to locate it; "
            "calibrate on a full white frame taken with the condenser fully open"
        )
    r = optimize.least_squares(lambda p: (model(p) - b) / s0, p0, method="lm", x_scale="jac")
    s = r.x[2]
    if not s > 0:
        raise SsdpcError(
            "the elemental-image brightness does not follow the objective pupil; "
            "calibrate on a white frame taken with the condenser fully open"
        )
    rms = float(np.sqrt(np.mean((model(r.x) - b) ** 2))) / s
    try:
        cov = np.linalg.inv(r.jac.T @ r.jac) * np.sum(r.fun**2) / max(len(b) - len(p0), 1)
        sig = float(math.sqrt(max(cov[0, 0] + cov[1, 1], 0) / 2))
    except np.linalg.LinAlgError:
        sig = np.inf
    return np.array(r.x[:2]), rms, sig, r.x


def content_score(img, centres, radius) -> float:
    """How much structure the interior of the lit EIs holds, in units of its noise: the
    median over EIs of the rms of a local mean, after removing a quadratic surface (the
    illumination fall-off), against the noise of that mean. About 1 on an empty EI;
    NaN when the EIs are too small to tell (under 24 px across).

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, camera units, dark level removed.
    centres : ndarray, (K, 2)
        Centres (x, y) of the lit EIs, px.
    radius : float
        EI radius, px.

    Returns
    -------
    float
    """
    r = int(0.6 * radius)
    k = int(min(9, max(3, r // 3)))
    if r < 12:
        return float("nan")
    stats = []
    for cx, cy in centres:
        x0, y0 = int(round(cx)) - r, int(round(cy)) - r
        if x0 < 0 or y0 < 0 or x0 + 2 * r >= img.shape[1] or y0 + 2 * r >= img.shape[0]:
            continue
        patch = img[y0 : y0 + 2 * r, x0 : x0 + 2 * r].astype(float)
        noise = np.median(np.abs(np.diff(patch, axis=1))) / (0.6745 * math.sqrt(2)) + 1e-9
        lo = ndimage.uniform_filter(patch, k)[k:-k, k:-k]
        yy, xx = (v.ravel() / lo.shape[0] - 0.5 for v in np.mgrid[: lo.shape[0], : lo.shape[1]])
        G = np.stack([np.ones(lo.size), xx, yy, xx * xx, xx * yy, yy * yy], 1)
        resid = lo.ravel() - G @ np.linalg.lstsq(G, lo.ravel(), rcond=None)[0]
        stats.append(np.std(resid) / (noise / k))
    return float(np.median(stats)) if stats else float("nan")


#: content score above which a frame holds a sample
SAMPLE_SCORE = 5.0
#: lit lenslets / lenslets in the pupil above which the whole pupil is lit
FULL_PUPIL = 0.6


def pupil_lenslets(optics, n_cells: int) -> int:
    """Lenslets at least a quarter inside the objective pupil, at most as many as the sensor
    holds (``n_cells`` lattice cells): what a white frame lights.

    Parameters
    ----------
    optics : Optics
    n_cells : int
        Lattice cells on the sensor.

    Returns
    -------
    int
    """
    return max(1, min(sum(1 for ln in nominal_lenslets(optics) if ln.fraction >= 0.25), n_cells))


def decide_kind(img, b, centres, r_ei, optics) -> tuple[str, bool, dict]:
    """Kind of frame, whether its lit pattern fills the objective pupil, and the evidence.

    A frame with structure inside its EIs is a "sample" frame; otherwise it is "white"
    when about as many EIs are lit as lenslets lie in the pupil, else "flat". The evidence
    holds the counts, the content score and "clear" or "borderline" for how sure that is.

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, camera units, dark level removed.
    b : ndarray, (K,)
        Brightness of each EI, camera units.
    centres : ndarray, (K, 2)
        EI centres (x, y), px.
    r_ei : float
        EI radius, px.
    optics : Optics

    Returns
    -------
    kind : {'white', 'flat', 'sample'}
    full : bool
        The lit EIs fill the objective pupil.
    evidence : dict
    """
    ok = np.isfinite(b)
    floor = float(np.percentile(b[ok], 5))
    # the dim EIs give the floor; where every EI is lit (the pupil larger than the sensor) the
    # floor is the dark level, already removed
    bb = b[ok] - (floor if floor < 0.5 * float(b[ok].max()) else 0.0)
    n_lit = int(np.count_nonzero(bb > 0.25 * bb.max()))
    n_pupil = pupil_lenslets(optics, int(ok.sum()))
    score = content_score(img, centres, r_ei)
    full = n_lit >= FULL_PUPIL * n_pupil
    has_content = bool(np.isfinite(score) and score > SAMPLE_SCORE)
    kind = "sample" if has_content else ("white" if full else "flat")
    ratio = n_lit / n_pupil
    near = abs(ratio - FULL_PUPIL) < 0.15 or (
        np.isfinite(score) and abs(math.log(max(score, 1e-3) / SAMPLE_SCORE)) < 0.5
    )
    evidence = {
        "lit_lenslets": n_lit,
        "pupil_lenslets": int(n_pupil),
        "content_score": None if not np.isfinite(score) else round(float(score), 2),
        "certainty": "borderline" if near else "clear",
    }
    return kind, full, evidence
