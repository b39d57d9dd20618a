"""Elemental-image (EI) disks on a raw frame: detection, robust rim circles, sub-pixel rim fits.

Every EI is the image of the field stop, a bright disk with a soft rim. Three steps
find and measure the disks, each tolerant to what real frames hold (sample content,
dust, the shadow of a lens mount at the rim, vignetting, 8-bit quantisation):

1. ``find_disks``: a ring filter (mean just inside the expected rim minus mean just
   outside it) responds to the rim only, so content inside the EI barely moves its peak.
2. ``rim_circle``: along rays from the rough centre, the steepest falling edge near the
   expected radius gives one rim point per ray; a circle fitted with a robust loss and
   then refitted to its inliers rejects notches, dust and content edges.
3. ``fit_rim``: a soft-edged disk (erfc rim) x linear brightness ramp + a linear
   background (a brighter neighbour's skirt) fitted to
   the pixels of the rim annulus on the inlier rays only, away from the neighbours'
   touching points: the sub-pixel centre and its uncertainty.

Coordinates: x = column, y = row, pixel centres at integers. Lengths in pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, optimize, signal
from scipy.special import erfc

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.statistics import robust_sigma

#: the 20 % quantile of |N(0, 1)|: turns the 20th percentile of |differences| into σ
_Q20 = 0.2533
#: relative radii of the ring filter bank (the optics' EI radius may be off by a few %)
_RING_SCALES = (0.94, 1.0, 1.06)
#: a disk is "there" when the ring response beats its noise by this factor
MIN_SNR = 12.0


def noise_sigma(img: np.ndarray) -> float:
    """Pixel noise (rms, frame units) that the lattice's edges do not inflate.

    Differences of neighbouring pixels are noise plus structure; structure (EI rims, the
    lattice) only makes them larger. The 20th percentile of |difference| in x and y
    therefore comes from the flat parts of the frame (EI interiors, dark gaps) even when
    rims cover most of it, as on a 15 px pitch. Integer frames get at least the
    quantisation noise 1/√12.

    Parameters
    ----------
    img : ndarray (H, W) float

    Returns
    -------
    float
    """
    sub = img[::2, ::2] if img.size > 4_000_000 else img
    d = np.concatenate([np.abs(np.diff(sub, axis=1)).ravel(), np.abs(np.diff(sub, axis=0)).ravel()])
    sigma = float(np.percentile(d, 20)) / (math.sqrt(2) * _Q20)
    integral = bool(np.all(sub[:64, :64] == np.round(sub[:64, :64])))
    floor = 1 / math.sqrt(12) if integral else 1e-6 * float(np.ptp(sub))
    return max(sigma, floor, 1e-12)


def _bin(img, b):
    H, W = (s // b * b for s in img.shape)
    return img[:H, :W].reshape(H // b, b, W // b, b).mean(axis=(1, 3))


def _ring_kernel(radius, width):
    """Mean over [R - 2w, R) minus mean over [R, R + 2w): zero-mean, peaks on a disk's centre."""
    m = int(math.ceil(radius + 2 * width)) + 1
    yy, xx = np.mgrid[-m : m + 1, -m : m + 1]
    rho = np.hypot(xx, yy)
    inner = (rho >= radius - 2 * width) & (rho < radius)
    outer = (rho >= radius) & (rho < radius + 2 * width)
    return inner / max(inner.sum(), 1) - outer / max(outer.sum(), 1)


@dataclass
class Candidates:
    """Rough EI centres from the ring filter.

    ``xy`` (K, 2) px; ``strength`` (K,) ring response (rim contrast, frame units);
    ``noise`` the pixel noise; ``dark`` the dark level (2nd percentile)."""

    xy: np.ndarray
    strength: np.ndarray
    noise: float
    dark: float


def find_disks(img: np.ndarray, pitch: float, radius: float) -> Candidates:
    """Rough centres of the EI disks of about ``radius`` px on a lattice of about ``pitch`` px.

    Raises SsdpcError when no disk stands out of the noise.

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, camera units, dark level removed.
    pitch : float
        Expected lenslet pitch, px.
    radius : float
        Expected EI radius, px.

    Returns
    -------
    Candidates
        Rough centres (x, y) px and their strengths.
    """
    from skimage.feature import peak_local_max

    b = max(1, int(pitch // 40))
    small = _bin(img, b)
    noise = noise_sigma(img)
    R = radius / b
    w = max(0.75, 0.06 * R)
    response = np.full(small.shape, -np.inf, np.float32)
    worst_gain = 0.0
    for s in _RING_SCALES:
        k = _ring_kernel(s * R, w)
        response = np.maximum(response, signal.fftconvolve(small, k, mode="same").astype(np.float32))
        worst_gain = max(worst_gain, float(np.sqrt(np.sum(k * k))))
    resp_noise = noise / b * worst_gain
    m = int(math.ceil(max(_RING_SCALES) * R + 2 * w)) + 2  # the zero padding beyond the frame is no rim
    if min(response.shape) <= 2 * m + 2:
        raise SsdpcError(
            f"frame {img.shape} is too small for elemental images of radius {radius:.0f} px; "
            "check mla.pitch_um and sensor.pixel_um in the optics file"
        )
    response[:m] = response[-m:] = -np.inf
    response[:, :m] = response[:, -m:] = -np.inf
    top = float(response.max())
    dark = float(np.percentile(small, 2))
    if not top > MIN_SNR * resp_noise:
        raise SsdpcError(
            f"no elemental images found (rim contrast {top:.3g} vs noise {resp_noise:.3g}); "
            "record a white frame with the lamp on, the condenser fully open and a longer exposure"
        )
    pk = peak_local_max(
        response,
        min_distance=max(1, int(0.35 * pitch / b)),
        threshold_abs=max(MIN_SNR * resp_noise, 0.1 * top),
        exclude_border=False,
    )
    xy = np.stack([pk[:, 1] * b + (b - 1) / 2, pk[:, 0] * b + (b - 1) / 2], 1).astype(float)
    return Candidates(xy.reshape(-1, 2), response[pk[:, 0], pk[:, 1]].astype(float), noise, dark)


# ------------------------------------------------------------------ rim circle
@dataclass
class Circle:
    """A fitted EI rim: centre (x, y) px, radius px, the rms of the inlier rim points about
    it (px), the fraction of usable rays that are inliers, the ray angles (rad), which
    were inliers, and the median rim slope on them (frame units per px)."""

    centre: np.ndarray
    radius: float
    rms: float
    inlier_frac: float
    angles: np.ndarray
    inliers: np.ndarray
    edge: float = 0.0


def rim_circle(img: np.ndarray, c0, radius: float, reach: float = 0.25, neighbours=None) -> Circle | None:
    """Robust circle through the rim points of the EI near ``c0``.

    Each ray from ``c0`` is sampled from (1 - reach) R to (1 + reach) R; its steepest
    falling edge (smoothed profile, parabolic sub-sample peak) is a rim point. Rays that
    pass within (1 + reach/2) R of a neighbouring EI centre (``neighbours`` (N, 2)) are
    not used: there the neighbour's rim and skirt would pull the edge. Weak edges (below
    a quarter of the median) are dropped; a circle is fitted with a Cauchy loss, points
    beyond 3 robust sigmas are rejected and the circle is refitted by least squares.
    None when too few rim points agree.

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, camera units, dark level removed.
    c0 : array_like, (2,)
        Start centre (x, y), px.
    radius : float
        Expected radius R, px.
    reach : float
        Search range about R, as a fraction of R.
    neighbours : ndarray, (N, 2), optional
        Centres (x, y) px of the neighbouring EIs.

    Returns
    -------
    Circle or None
    """
    c0 = np.asarray(c0, float)
    n_ray = int(np.clip(2 * math.pi * radius / 1.5, 32, 360))
    phi = np.arange(n_ray) * (2 * math.pi / n_ray)
    step = 0.5 if radius < 100 else radius / 200
    r = np.arange((1 - reach) * radius, (1 + reach) * radius + step, step)
    xs = c0[0] + np.cos(phi)[:, None] * r[None, :]
    ys = c0[1] + np.sin(phi)[:, None] * r[None, :]
    H, W = img.shape
    inside = (xs >= 0) & (xs <= W - 1) & (ys >= 0) & (ys <= H - 1)
    prof = ndimage.map_coordinates(img, [ys.ravel(), xs.ravel()], order=1, mode="nearest").reshape(xs.shape)
    prof = ndimage.gaussian_filter1d(prof, max(1.0, 0.5 / step), axis=1)
    der = np.gradient(prof, step, axis=1)
    j = np.argmin(der, axis=1)
    jj = np.clip(j, 1, len(r) - 2)
    a, b_, c = der[np.arange(n_ray), jj - 1], der[np.arange(n_ray), jj], der[np.arange(n_ray), jj + 1]
    den = a - 2 * b_ + c
    off = np.where(np.abs(den) > 1e-12, 0.5 * (a - c) / np.where(np.abs(den) > 1e-12, den, 1), 0.0)
    rim_r = r[jj] + np.clip(off, -1, 1) * step
    strength = -der[np.arange(n_ray), j]
    ok = inside.all(axis=1) & (j > 0) & (j < len(r) - 1) & (strength > 0)
    for q in np.asarray(neighbours if neighbours is not None else [], float).reshape(-1, 2):
        ok &= np.hypot(xs - q[0], ys - q[1]).min(axis=1) > (1 + 0.5 * reach) * radius
    usable = int(ok.sum())
    if usable < 8:
        return None
    ok &= strength > 0.25 * np.median(strength[ok])
    px = c0[0] + rim_r * np.cos(phi)
    py = c0[1] + rim_r * np.sin(phi)
    if ok.sum() < 8:
        return None

    def resid(p, sel):
        return np.hypot(px[sel] - p[0], py[sel] - p[1]) - p[2]

    scale = max(0.5, 0.004 * radius)
    p = np.array([c0[0], c0[1], float(np.median(rim_r[ok]))])
    p = optimize.least_squares(resid, p, args=(ok,), loss="cauchy", f_scale=scale).x
    res = np.abs(np.hypot(px - p[0], py - p[1]) - p[2])
    sig = max(robust_sigma(res[ok], about=0.0), 0.25 * scale)
    inl = ok & (res < 3 * sig)
    if inl.sum() < max(8, 0.3 * usable):
        return None
    p = optimize.least_squares(resid, p, args=(inl,)).x
    res = np.hypot(px - p[0], py - p[1]) - p[2]
    return Circle(
        np.array(p[:2]),
        float(p[2]),
        float(np.sqrt(np.mean(res[inl] ** 2))),
        float(inl.sum() / usable),
        phi,
        inl,
        float(np.median(strength[inl])),
    )


# ------------------------------------------------------------ sub-pixel rim fit
def _edge_model(p, x, y, c0, r0, jac=False):
    """Soft-edged disk (erfc rim of width w) x linear ramp, on a linear background ramp
    (a brighter neighbour's skirt); its Jacobian if ``jac``."""
    cx, cy, R, w, a0, a1, a2, bg, b1, b2 = p
    dx, dy = x - cx, y - cy
    rho = np.hypot(dx, dy) + 1e-9
    t = (rho - R) / w
    D = 0.5 * erfc(t / math.sqrt(2))
    u, v = (x - c0[0]) / r0, (y - c0[1]) / r0
    A = a0 + a1 * u + a2 * v
    if not jac:
        return bg + b1 * u + b2 * v + A * D
    Ag = A * np.exp(-0.5 * t * t) / (math.sqrt(2 * math.pi) * w)
    one = np.ones_like(D)
    return np.stack([Ag * dx / rho, Ag * dy / rho, Ag, Ag * t, D, D * u, D * v, one, u, v], 1)


def _edge_residual(p, x, y, z, c0, r0, scale):
    return (_edge_model(p, x, y, c0, r0) - z) / scale


def _edge_jac(p, x, y, z, c0, r0, scale):
    return _edge_model(p, x, y, c0, r0, jac=True) / scale


@dataclass
class RimFit:
    """Sub-pixel EI rim: centre (x, y) px, radius px (of the disk before its blur), rim width
    px, brightness (frame units above the offset), centre uncertainty σ px."""

    centre: np.ndarray
    radius: float
    width: float
    level: float
    sigma: float


def fit_rim(img, circle: Circle, neighbours, delta: float, dark: float) -> RimFit | None:
    """Soft-disk fit on the annulus |ρ - R| < δ around ``circle``.

    Pixels on rays that ``rim_circle`` rejected (a notch, dust, content on the rim) and
    pixels within R + δ of a neighbouring EI centre (``neighbours`` (N, 2)) are left out;
    after a first fit, pixels beyond 5 robust sigmas are dropped and the fit repeated.
    None when fewer than 40 pixels are left (touching EIs of a 15 px pitch keep about 50) or
    the fit does not converge near the circle.

    Parameters
    ----------
    img : ndarray, float, (H, W)
        The frame, camera units, dark level removed.
    circle : Circle
        From :func:`rim_circle`.
    neighbours : ndarray, (N, 2)
        Neighbouring EI centres (x, y), px.
    delta : float
        Half width δ of the annulus, px.
    dark : float
        Level outside the EIs, camera units.

    Returns
    -------
    RimFit or None
        Centre (x, y) px, radius px, edge width px and the centre's standard error.
    """
    c0, r0 = circle.centre, circle.radius
    H, W = img.shape
    x0, x1 = int(max(c0[0] - r0 - delta - 1, 0)), int(min(c0[0] + r0 + delta + 2, W))
    y0, y1 = int(max(c0[1] - r0 - delta - 1, 0)), int(min(c0[1] + r0 + delta + 2, H))
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(float)
    rho = np.hypot(xx - c0[0], yy - c0[1])
    keep = np.abs(rho - r0) < delta
    n_ray = len(circle.angles)
    ray = np.rint(np.mod(np.arctan2(yy - c0[1], xx - c0[0]), 2 * math.pi) / (2 * math.pi) * n_ray).astype(int) % n_ray
    keep &= circle.inliers[ray]
    for q in np.asarray(neighbours, float).reshape(-1, 2):
        keep &= np.hypot(xx - q[0], yy - q[1]) > r0 + delta
    x, y, z = xx[keep], yy[keep], img[y0:y1, x0:x1][keep].astype(float)
    if z.size < 40:
        return None
    in_ring = rho[keep] < r0 - 0.5 * delta
    inner = float(np.median(z[in_ring])) if in_ring.any() else float(z.max())
    scale = max(inner - dark, 1e-6)
    p = np.array([c0[0], c0[1], r0, max(0.5, 0.1 * delta), inner - dark, 0.0, 0.0, dark, 0.0, 0.0])
    use = np.ones(z.size, bool)
    for _ in range(2):  # fit, then refit without outlying pixels
        try:
            r = optimize.least_squares(
                _edge_residual, p, jac=_edge_jac, method="lm", args=(x[use], y[use], z[use], c0, r0, scale)
            )
        except (ValueError, np.linalg.LinAlgError):
            return None
        p = r.x
        res = _edge_residual(p, x, y, z, c0, r0, scale)
        mad = robust_sigma(res[use], about=0.0) + 1e-12
        use = np.abs(res) < 5 * mad
    cx, cy, R, w, a0 = p[:5]
    moved = math.hypot(cx - c0[0], cy - c0[1])
    if not (r.success and a0 > 0 and 0.1 < w < delta and abs(R - r0) < 0.5 * delta and moved < 0.5 * delta):
        return None
    s2 = float(np.sum(r.fun**2)) / max(r.fun.size - 10, 1)
    try:
        cov = np.linalg.inv(r.jac.T @ r.jac) * s2
    except np.linalg.LinAlgError:
        return None
    sig = float(math.sqrt(max(cov[0, 0] + cov[1, 1], 0) / 2))
    # a blurred disk's half-level contour lies w²/(2R) inside its edge (the blur reaches further
    # into the outside of a convex rim): the disk's own radius, within 0.1 % up to w = R/5
    return RimFit(np.array([cx, cy]), float(R + w * w / (2 * R)), float(w), float(a0), sig)
