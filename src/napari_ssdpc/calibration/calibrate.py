"""Lenslet-grid calibration and elemental-image (EI) extraction.

``calibrate(frame, optics)`` measures everything from the frame; the optics are a prior
(pitch, EI radius, pupil radius) and a consistency check:

1. Lattice. A disk filter finds the lit EIs; their neighbour vectors give a first
   pitch and rotation. Each EI centre is then fitted to sub-pixel precision from its own
   edge (a soft-edged disk times a linear brightness ramp, fitted only on an annulus
   around the rim and away from the touching points of neighbouring EIs), so smooth
   illumination gradients, dimmed edge lenslets and the sample inside the field do not
   bias it. A weighted least-squares fit of one square lattice (vertex, pitch, rotation)
   to all centres gives the grid; its rms residual is a sanity check.
2. Optical axis. The MLA sits in a plane conjugate to the objective's back focal plane
   (paper §2, Fig. 1), so the objective pupil appears on the MLA as a disk of radius
   ``f_obj NA m_r`` and each EI's brightness is proportional to the part of its lenslet
   inside that disk. On a white frame (condenser fully open, σ = 1) we fit the axis so
   that EI brightness = offset + scale x (smooth illumination envelope: tilt and
   radial quadratic about the axis) x
   ``circle_overlap_fraction(|a_k|, r_ml, pupil_radius_mla_um)``.
   On a flat or sample frame (σ < 1) only the lenslets that see the condenser disk
   are lit; the same fit with the source radius ``σ x pupil radius`` gives the axis,
   less precisely (a warning says so). With fewer than three lit EIs the lattice is
   undetermined and we ask for a white frame.

``extract_views`` resamples every EI onto an upright object-aligned grid (rotation and
flips undone), ``insert_views`` puts views back on the sensor, ``overlay_png`` draws the
detected grid for a check by eye. Coordinates follow ``grid.py``: x = column, y = row,
pixel centres at integers.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage, optimize, signal
from scipy.special import erfc

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.files import atomic_write
from napari_ssdpc.physics.lattice import Grid, xy_pair
from napari_ssdpc.settings.optics import Lenslet, Optics, circle_overlap_fraction

CALIBRATION_FORMAT = "napari-ssdpc-calibration"
CALIBRATION_VERSION = 1
KINDS = ("auto", "white", "flat", "sample")

PITCH_TOLERANCE = 0.03  # measured pitch may differ from the optics' prior by 3%
MAX_LATTICE_RMS_PX = 0.5  # rms of EI centres about the fitted lattice
MAX_AXIS_RMS = 0.05  # rms of the brightness-pattern fit, relative to full brightness
MIN_EIS = 3  # EIs needed to fix a lattice (two fix it, a third checks it)
# EI brightness is the mean inside this fraction of the EI radius: the centre, away from
# the diffraction-blurred rim, without a sample; nearly the whole EI with a sample, which
# moves light around inside the EI but mostly keeps it there.
_INNER = {"white": 0.5, "flat": 0.5, "sample": 0.85}


# ---------------------------------------------------------------- data classes
@dataclass(eq=False)
class Calibration:
    """Lenslet grid measured on one frame.

    ``lenslets`` (from ``grid.lenslets(optics)``) and ``centres_px`` (x, y per lenslet)
    form the per-lenslet table; ``brightness`` is each EI's measured brightness relative
    to a fully lit lenslet (≈ ``fraction`` on a white frame, NaN where the EI leaves the
    frame). ``residual_px`` is the rms of the fitted EI centres about the lattice and
    ``axis_rms`` the relative rms of the brightness-pattern fit that gave the axis.
    """

    grid: Grid
    ei_radius_px: float
    optics: Optics
    frame_shape: tuple[int, int]
    lenslets: list[Lenslet]
    centres_px: np.ndarray
    brightness: np.ndarray
    residual_px: float
    axis_rms: float
    kind: str
    n_fitted: int = 0
    version: int = CALIBRATION_VERSION

    # ------------------------------------------------------------- table
    @property
    def table(self) -> list[dict]:
        """One dict per lenslet: row, col, centre_px, a_um, u, fraction, halves, brightness."""
        out = []
        for ln, c, b in zip(self.lenslets, self.centres_px, self.brightness):
            out.append(
                {
                    "row": ln.row,
                    "col": ln.col,
                    "centre_px": [float(c[0]), float(c[1])],
                    "a_um": [float(v) for v in ln.a_um],
                    "u": [float(v) for v in ln.u],
                    "fraction": float(ln.fraction),
                    "halves": list(ln.halves),
                    "brightness": None if not np.isfinite(b) else float(b),
                }
            )
        return out

    def check_frame(self, frame, name="frame") -> np.ndarray:
        """Validate a frame against this calibration; return it as float32."""
        img = _validated(frame, name)
        if img.shape != tuple(self.frame_shape):
            raise SsdpcError(
                f"{name}: shape {img.shape} differs from the calibration's {tuple(self.frame_shape)}; "
                "use frames from the same camera ROI and binning, or calibrate on a white frame "
                "of this shape"
            )
        return img

    # ------------------------------------------------------------- JSON
    def to_dict(self) -> dict:
        return {
            "format": CALIBRATION_FORMAT,
            "version": self.version,
            "kind": self.kind,
            "frame_shape": [int(v) for v in self.frame_shape],
            "axis_px": [float(v) for v in self.grid.axis_px],
            "pitch_px": float(self.grid.pitch_px),
            "rotation_deg": float(self.grid.rotation_deg),
            "ei_radius_px": float(self.ei_radius_px),
            "residual_px": float(self.residual_px),
            "axis_rms": float(self.axis_rms),
            "n_fitted": int(self.n_fitted),
            "grid": self.grid.to_dict(),
            "lenslets": self.table,
            "optics": self.optics.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict, source: str = "calibration") -> Calibration:
        if not isinstance(d, dict) or d.get("format") != CALIBRATION_FORMAT:
            raise SsdpcError(f"{source}: not a napari-ssdpc calibration file; run `ssdpc calibrate` on a white frame")
        if d.get("version") != CALIBRATION_VERSION:
            raise SsdpcError(
                f"{source}: calibration version {d.get('version')!r} is not supported "
                f"(this software reads version {CALIBRATION_VERSION}); re-run `ssdpc calibrate`"
            )
        try:
            optics = Optics.from_dict(d["optics"], source=f"{source} optics")
            grid = Grid.from_dict(d["grid"])
            rows = d["lenslets"]
            lenslets = [
                Lenslet(
                    int(r["row"]),
                    int(r["col"]),
                    xy_pair(r["a_um"]),
                    xy_pair(r["u"]),
                    float(r["fraction"]),
                )
                for r in rows
            ]
            centres = np.array([r["centre_px"] for r in rows], dtype=float).reshape(-1, 2)
            bright = np.array([np.nan if r.get("brightness") is None else r["brightness"] for r in rows], float)
            return cls(
                grid=grid,
                ei_radius_px=float(d["ei_radius_px"]),
                optics=optics,
                frame_shape=(int(d["frame_shape"][0]), int(d["frame_shape"][1])),
                lenslets=lenslets,
                centres_px=centres,
                brightness=bright,
                residual_px=float(d["residual_px"]),
                axis_rms=float(d["axis_rms"]),
                kind=str(d["kind"]),
                n_fitted=int(d.get("n_fitted", 0)),
                version=int(d["version"]),
            )
        except SsdpcError:
            raise
        except (KeyError, TypeError, ValueError) as e:
            raise SsdpcError(
                f"{source}: corrupt calibration ({type(e).__name__}: {e}); re-run `ssdpc calibrate`"
            ) from None

    def to_json(self, path) -> Path:
        """Write the versioned JSON atomically (a failure never leaves a half file)."""
        path = Path(path)
        text = json.dumps(self.to_dict(), indent=1)
        with atomic_write(path) as tmp:
            tmp.write_text(text)
        return path

    @classmethod
    def from_json(cls, path) -> Calibration:
        path = Path(path)
        if not path.is_file():
            raise SsdpcError(f"calibration file not found: {path} (run `ssdpc calibrate WHITE.tif -o {path.name}`)")
        try:
            d = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise SsdpcError(f"{path}: corrupt calibration JSON; re-run `ssdpc calibrate`") from None
        return cls.from_dict(d, source=str(path))


@dataclass(eq=False)
class Views:
    """Elemental images resampled on an upright object grid.

    ``data[k]`` (h, w) is the EI of ``lenslets[k]``; pixel (i, j) shows the in-focus
    object point (``x_um[j]``, ``y_um[i]``) µm, with (0, 0) on the EI centre. ``mask`` is
    the iris disk (True inside).
    """

    data: np.ndarray
    lenslets: list[Lenslet]
    centres_px: np.ndarray
    x_um: np.ndarray
    y_um: np.ndarray
    mask: np.ndarray
    pixel_um: float
    frame_shape: tuple[int, int] = (0, 0)

    @property
    def extent_um(self) -> tuple[float, float, float, float]:
        """matplotlib ``imshow`` extent (left, right, bottom, top) in µm."""
        h = 0.5 * self.pixel_um
        return (float(self.x_um[0] - h), float(self.x_um[-1] + h), float(self.y_um[-1] + h), float(self.y_um[0] - h))


# ------------------------------------------------------------------ validation
def _validated(frame, name="frame") -> np.ndarray:
    a = np.asarray(frame)
    if a.dtype.kind not in "uif":
        raise SsdpcError(
            f"{name}: dtype {a.dtype} is not a grey-level image; give the raw camera frame (integer or float)"
        )
    if a.ndim != 2:
        hint = "; pass one frame, e.g. frames[0]" if a.ndim == 3 else ""
        raise SsdpcError(f"{name}: expected a 2D frame (y, x), got shape {a.shape}{hint}")
    if min(a.shape) < 16:
        raise SsdpcError(f"{name}: shape {a.shape} is too small for a light-field frame; give the full camera frame")
    img = a.astype(np.float32, copy=False)
    if not np.all(np.isfinite(img)):
        bad = int(img.size - np.count_nonzero(np.isfinite(img)))
        raise SsdpcError(f"{name}: {bad} NaN/inf pixels; replace them or re-export the frame")
    return img


def _check_signal(raw, img):
    """Blank and saturated frames. Saturation counts pixels at the top code value of an
    integer frame (or a float frame whose maximum is 2^n - 1)."""
    lo, hi = float(img.min()), float(img.max())
    if hi - lo <= 0:
        raise SsdpcError(
            f"frame is blank (every pixel is {hi:g}); "
            "record a white frame with the lamp on and the condenser fully open"
        )
    codes = {2.0**n - 1 for n in range(8, 17)}
    if np.asarray(raw).dtype.kind in "ui" or hi in codes:
        bright = img > lo + 0.5 * (hi - lo)
        n_top = int(np.count_nonzero(img >= hi))
        if n_top > 50 and n_top > 5e-3 * np.count_nonzero(bright):
            raise SsdpcError(
                f"frame is saturated ({n_top} pixels at {hi:g}); "
                "shorten the exposure or dim the lamp and record it again"
            )


# ------------------------------------------------------------ lattice helpers
def _rot(theta_deg):
    t = math.radians(theta_deg)
    return np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])


@dataclass
class _Lattice:
    """EI centre of lattice index n = (col, row): origin + M @ n, M = pitch R(θ) F."""

    origin: np.ndarray
    pitch: float
    theta_deg: float
    flip: np.ndarray  # diag(±1, ±1)

    @property
    def M(self):
        return self.pitch * _rot(self.theta_deg) @ self.flip

    def centres(self, n):
        return self.origin + np.asarray(n, float) @ self.M.T

    def index(self, xy):
        return np.linalg.solve(self.M, (np.asarray(xy, float) - self.origin).T).T


def _fit_lattice(xy, n, flip, weights=None):
    """Weighted linear least squares of centres xy (K, 2) on indices n (K, 2):
    x = ox + α n'x − β n'y, y = oy + β n'x + α n'y with n' = F n, α + iβ = p e^{iθ}."""
    xy, n = np.asarray(xy, float), np.asarray(n, float)
    w = np.ones(len(xy)) if weights is None else np.asarray(weights, float)
    nf = n @ flip.T
    one, zero = np.ones(len(n)), np.zeros(len(n))
    A = np.concatenate([np.stack([one, zero, nf[:, 0], -nf[:, 1]], 1), np.stack([zero, one, nf[:, 1], nf[:, 0]], 1)])
    b = np.concatenate([xy[:, 0], xy[:, 1]])
    sw = np.sqrt(np.concatenate([w, w]))
    sol = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)[0]
    lat = _Lattice(sol[:2].copy(), float(math.hypot(sol[2], sol[3])), math.degrees(math.atan2(sol[3], sol[2])), flip)
    res = xy - lat.centres(n)
    return lat, res


# --------------------------------------------------------- step 1: lit EIs
def _find_peaks(img, pitch0, radius0):
    """Centres (x, y) and levels (K, 3) of the lit EIs, and the dark level.

    A disk filter of radius R/2 on a binned frame has a plateau inside every lit EI
    that a brighter neighbour does not reach (its skirt ends 1.5 R from its centre);
    each local maximum (searched within ±0.12 pitch, so a dim EI beside a bright one
    keeps its own) is moved to the centroid of its half-maximum disk, and duplicates
    on one plateau are merged."""
    from skimage.feature import peak_local_max

    b = max(1, int(pitch0 // 48))
    H, W = (s // b * b for s in img.shape)
    small = img[:H, :W].reshape(H // b, b, W // b, b).mean(axis=(1, 3))
    rb = max(1.5, 0.5 * radius0 / b)
    yy, xx = np.mgrid[-int(rb) : int(rb) + 1, -int(rb) : int(rb) + 1]
    disk = (xx**2 + yy**2 <= rb * rb).astype(np.float32)
    smooth = signal.fftconvolve(small, disk / disk.sum(), mode="same")
    dark = float(np.percentile(small, 2))
    noise = float(np.median(np.abs(np.diff(small, axis=1)))) / (0.6745 * math.sqrt(2)) + 1e-12
    m = int(rb) + 1
    contrast = float(smooth[m:-m, m:-m].max()) - dark
    if not contrast > 20 * noise:
        raise SsdpcError(
            f"no elemental images found (contrast {contrast:.3g} vs noise {noise:.3g}); "
            "record a white frame with the lamp on, the condenser fully open and a longer exposure"
        )
    pk = peak_local_max(
        smooth, min_distance=max(1, int(0.12 * pitch0 / b)), threshold_abs=dark + 0.04 * contrast, exclude_border=False
    )
    pts = []
    for r, c in pk:
        xy = _disk_centroid(img, np.array([c * b + (b - 1) / 2, r * b + (b - 1) / 2]), radius0, dark)
        if (
            xy is not None
            and radius0 + 2 < xy[0] < img.shape[1] - 3 - radius0
            and radius0 + 2 < xy[1] < img.shape[0] - 3 - radius0
        ):  # the whole disk in the frame
            if all(math.hypot(*(xy - q[:2])) > 0.3 * pitch0 for q in pts):
                pts.append(np.array([xy[0], xy[1], smooth[r, c] - dark]))
    return np.array(pts).reshape(-1, 3), dark


def _disk_centroid(img, c, radius, dark, iterations=4):
    """Centroid of the pixels above half the EI level within R + 3 px of ``c`` (iterated)."""
    H, W = img.shape
    for _ in range(iterations):
        x0, x1 = int(max(c[0] - radius - 4, 0)), int(min(c[0] + radius + 5, W))
        y0, y1 = int(max(c[1] - radius - 4, 0)), int(min(c[1] + radius + 5, H))
        if x1 - x0 < 3 or y1 - y0 < 3:
            return None
        yy, xx = np.mgrid[y0:y1, x0:x1]
        patch = img[y0:y1, x0:x1]
        rho2 = (xx - c[0]) ** 2 + (yy - c[1]) ** 2
        level = np.median(patch[rho2 < (0.4 * radius) ** 2]) - dark
        sel = (rho2 <= (radius + 3) ** 2) & (patch - dark > 0.5 * level)
        if level <= 0 or sel.sum() < 10:
            return None
        c = np.array([xx[sel].mean(), yy[sel].mean()])
    return c


def _coarse_lattice(pts, pitch0, flip):
    """Lattice from peak positions: neighbour vectors give pitch and rotation (mod 90°)."""
    if len(pts) < MIN_EIS:
        raise SsdpcError(
            f"only {len(pts)} lit elemental image(s) found, at least {MIN_EIS} are needed to fix the "
            "lattice; calibrate on a white frame taken with the condenser fully open"
        )
    xy = pts[:, :2]
    d = xy[None, :, :] - xy[:, None, :]
    dist = np.hypot(d[..., 0], d[..., 1])
    np.fill_diagonal(dist, np.inf)
    p_nn = float(np.median(dist.min(axis=1)))
    sel = np.abs(dist - p_nn) < 0.2 * p_nn
    if not sel.any():
        raise SsdpcError("lit spots do not form a lattice; check that the frame is a raw light-field frame")
    vec = d[sel]
    theta = math.degrees(np.angle(np.mean(np.exp(4j * np.arctan2(vec[:, 1], vec[:, 0]))))) / 4
    pitch = float(np.median(dist[sel]))
    ref = xy[np.argmax(pts[:, 2])]
    nprime = np.rint((xy - ref) @ _rot(theta) / pitch)  # R(−θ) (x − ref) / p, row vectors
    n = nprime @ flip.T
    lat, res = _fit_lattice(xy, n, flip)
    on = np.hypot(res[:, 0], res[:, 1]) < 0.15 * pitch
    if on.sum() < MIN_EIS or on.mean() < 0.8:
        raise SsdpcError(
            f"only {on.sum()} of {len(xy)} lit spots lie on a square lattice of pitch {pitch:.1f} px "
            f"(optics: {pitch0:.1f} px); check mla.pitch_um and sensor.pixel_um, and that the frame "
            "is a raw light-field frame of this instrument"
        )
    lat, _ = _fit_lattice(xy[on], n[on], flip)
    if abs(lat.pitch / pitch0 - 1) > PITCH_TOLERANCE:
        raise SsdpcError(
            f"lenslet pitch on the frame is {lat.pitch:.2f} px but the optics give {pitch0:.2f} px "
            "(mla.pitch_um / sensor.pixel_um); fix mla.pitch_um or sensor.pixel_um (binning?) "
            "in the optics file"
        )
    return lat, n[on]


# ---------------------------------------------------- step 2: EI edge fits
def _edge_model(p, x, y, c0, r0, jac=False):
    """Soft-edged disk (erfc rim of width w) x linear ramp + offset; its Jacobian if ``jac``."""
    cx, cy, R, w, a0, a1, a2, bg = p
    dx, dy = x - cx, y - cy
    rho = np.hypot(dx, dy) + 1e-9
    t = (rho - R) / w
    D = 0.5 * erfc(t / math.sqrt(2))
    u, v = (x - c0[0]) / r0, (y - c0[1]) / r0
    A = a0 + a1 * u + a2 * v
    if not jac:
        return bg + A * D
    Ag = A * np.exp(-0.5 * t * t) / (math.sqrt(2 * math.pi) * w)
    return np.stack([Ag * dx / rho, Ag * dy / rho, Ag, Ag * t, D, D * u, D * v, np.ones_like(D)], 1)


def _edge_residual(p, x, y, z, c0, r0, scale):
    return (_edge_model(p, x, y, c0, r0) - z) / scale


def _edge_jac(p, x, y, z, c0, r0, scale):
    return _edge_model(p, x, y, c0, r0, jac=True) / scale


def _fit_ei(img, c0, r0, lat, delta, dark):
    """Sub-pixel EI centre from its rim: soft disk x linear ramp + offset, fitted on
    |ρ − R| < δ away from the neighbours' touching points. Returns (cx, cy, R, w, a0,
    σ_centre) or None."""
    H, W = img.shape
    x0, x1 = int(max(c0[0] - r0 - delta - 1, 0)), int(min(c0[0] + r0 + delta + 2, W))
    y0, y1 = int(max(c0[1] - r0 - delta - 1, 0)), int(min(c0[1] + r0 + delta + 2, H))
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(float)
    rho = np.hypot(xx - c0[0], yy - c0[1])
    keep = np.abs(rho - r0) < delta
    n0 = lat.index(c0)
    for dc in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)):
        q = lat.centres(n0 + np.array(dc))
        keep &= np.hypot(xx - q[0], yy - q[1]) > r0 + delta
    x, y, z = xx[keep], yy[keep], img[y0:y1, x0:x1][keep].astype(float)
    if z.size < 200:
        return None
    inner = np.median(z[rho[keep] < r0 - 0.5 * delta]) if np.any(rho[keep] < r0 - 0.5 * delta) else z.max()
    scale = max(inner - dark, 1e-6)
    p = np.array([c0[0], c0[1], r0, 2.0, inner - dark, 0.0, 0.0, dark])
    use = np.ones(z.size, bool)
    for _ in range(2):  # fit, then refit without outlying pixels (dust, sample detail on the rim)
        xs, ys, zs = x[use], y[use], z[use]
        try:
            r = optimize.least_squares(_edge_residual, p, jac=_edge_jac, method="lm", args=(xs, ys, zs, c0, r0, scale))
        except (ValueError, np.linalg.LinAlgError):
            return None
        p = r.x
        res = _edge_residual(p, x, y, z, c0, r0, scale)
        mad = 1.4826 * np.median(np.abs(res[use])) + 1e-12
        use = np.abs(res) < 5 * mad
    cx, cy, R, w, a0 = p[:5]
    if not (
        r.success and a0 > 0 and 0.2 < w < delta and abs(R - r0) < delta and math.hypot(cx - c0[0], cy - c0[1]) < delta
    ):
        return None
    s2 = float(np.sum(r.fun**2)) / max(r.fun.size - 8, 1)
    try:
        cov = np.linalg.inv(r.jac.T @ r.jac) * s2
    except np.linalg.LinAlgError:
        return None
    sig = float(math.sqrt(max(cov[0, 0] + cov[1, 1], 0) / 2))
    return (cx, cy, R, w, a0, sig)


def _refine_lattice(img, lat, n_idx, r0, dark, delta):
    """Edge-fit every lit EI and fit one lattice to all centres (weights 1/σ²)."""
    fits, idx = [], []
    for n in n_idx:
        c0 = lat.centres(n)
        f = _fit_ei(img, c0, r0, lat, delta, dark)
        if f is not None and f[5] < 0.5:
            fits.append(f)
            idx.append(n)
    if len(fits) < MIN_EIS:
        raise SsdpcError(
            f"only {len(fits)} elemental image rims could be fitted (need {MIN_EIS}); "
            "calibrate on a white frame taken with the condenser fully open"
        )
    fits, idx = np.array(fits), np.array(idx)
    wgt = 1.0 / np.maximum(fits[:, 5], 1e-3) ** 2
    lat2, res = _fit_lattice(fits[:, :2], idx, lat.flip, wgt)
    rr = np.hypot(res[:, 0], res[:, 1])
    bad = rr > max(5 * np.median(rr), 0.5)  # drop outliers once (e.g. a dust speck on a rim)
    if bad.any() and (~bad).sum() >= MIN_EIS:
        fits, idx, wgt = fits[~bad], idx[~bad], wgt[~bad]
        lat2, res = _fit_lattice(fits[:, :2], idx, lat.flip, wgt)
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    return lat2, fits, idx, rms


# ------------------------------------------------- step 3: optical axis
def _ei_brightness(img, centres, radius, inner=0.5):
    """Mean of each EI inside ``inner`` x R (NaN where the disk leaves the frame)."""
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


def _all_cells(lat, shape):
    """Centres of every lattice cell whose centre lies in the frame."""
    H, W = shape
    corners = np.array([[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1]], float)
    ij = lat.index(corners)
    lo, hi = np.floor(ij.min(0)) - 1, np.ceil(ij.max(0)) + 1
    cc, rr = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
    n = np.stack([cc.ravel(), rr.ravel()], 1)
    xy = lat.centres(n)
    ok = (xy[:, 0] >= -0.5) & (xy[:, 0] <= W - 0.5) & (xy[:, 1] >= -0.5) & (xy[:, 1] <= H - 0.5)
    return xy[ok]


def _fit_axis(xy, b, radius_um, um_per_px, optics, tilt):
    """Axis (x, y) px from EI brightness b_k = c0 + s g_k f(|a_k|): f is the part of the
    lenslet inside the disk of ``radius_um`` on the MLA (objective pupil or condenser
    disk), g_k = 1 + g_x X + g_y Y + g_2 (X² + Y²) a smooth illumination envelope about
    the axis (``tilt``; X, Y in units of the pupil radius). Returns axis, rms/s,
    σ_axis and the parameters."""
    ok = np.isfinite(b)
    xy, b = xy[ok], b[ok]
    r_ml = optics.lenslet_radius_um
    c_guess = float(np.percentile(b, 10))
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


def _looks_like_sample(img, centres, radius):
    """True when the interior of the lit EIs holds structure well above the pixel noise:
    the rms of a 9x9 local mean, after removing a quadratic surface (the illumination
    fall-off), against the noise of that mean."""
    r = int(0.6 * radius)
    stats = []
    for cx, cy in centres:
        x0, y0 = int(round(cx)) - r, int(round(cy)) - r
        if x0 < 0 or y0 < 0 or x0 + 2 * r >= img.shape[1] or y0 + 2 * r >= img.shape[0]:
            continue
        patch = img[y0 : y0 + 2 * r, x0 : x0 + 2 * r].astype(float)
        noise = np.median(np.abs(np.diff(patch, axis=1))) / (0.6745 * math.sqrt(2)) + 1e-9
        lo = ndimage.uniform_filter(patch, 9)[5:-5, 5:-5]
        yy, xx = (v.ravel() / lo.shape[0] - 0.5 for v in np.mgrid[: lo.shape[0], : lo.shape[1]])
        G = np.stack([np.ones(lo.size), xx, yy, xx * xx, xx * yy, yy * yy], 1)
        resid = lo.ravel() - G @ np.linalg.lstsq(G, lo.ravel(), rcond=None)[0]
        stats.append(np.std(resid) / (noise / 9))
    return bool(stats) and float(np.median(stats)) > 5.0


# ------------------------------------------------------------------ calibrate
def calibrate(frame, optics: Optics, *, kind: str = "auto") -> Calibration:
    """Measure the lenslet grid and the optical axis on one raw frame.

    ``kind``: "white" (condenser fully open, σ = 1: the objective pupil edge gives the
    axis; the recommended input), "flat" or "sample" (the sample's condenser setting,
    σ < 1: the lit-lenslet pattern gives the axis, less precisely) or "auto" (decided
    from how many EIs are lit). Raises SsdpcError for unusable frames or optics that do
    not match the frame; never returns an unchecked grid.
    """
    if not isinstance(optics, Optics):
        raise SsdpcError(f"optics must be an Optics (e.g. Optics.from_yaml(path)), got {type(optics).__name__}")
    if kind not in KINDS:
        raise SsdpcError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    img = _validated(frame)
    _check_signal(frame, img)
    flip = np.diag([-1.0 if optics.flip_x else 1.0, -1.0 if optics.flip_y else 1.0])
    pitch0 = optics.pitch_px
    r0 = min(optics.ei_radius_px, 0.5 * pitch0)

    # 1. lattice: lit EIs -> coarse lattice -> rim fits -> least-squares lattice
    pts, dark = _find_peaks(img, pitch0, r0)
    lat, n_idx = _coarse_lattice(pts, pitch0, flip)
    lat, fits, idx, _ = _refine_lattice(img, lat, n_idx, r0, dark, delta=12.0)
    width = float(np.median(fits[:, 3]))
    r_ei = float(np.median(fits[:, 2]))
    delta = float(np.clip(5 * width + 2, 6, 0.3 * r_ei))
    lat, fits, idx, rms = _refine_lattice(img, lat, idx, r_ei, dark, delta=delta)
    r_ei = float(np.median(fits[:, 2]))
    if rms > MAX_LATTICE_RMS_PX:
        raise SsdpcError(
            f"elemental-image centres do not fit one square lattice (rms {rms:.2f} px); "
            "check that the frame is an undistorted raw light-field frame of this instrument"
        )
    if abs(lat.pitch / pitch0 - 1) > PITCH_TOLERANCE:
        raise SsdpcError(
            f"lenslet pitch on the frame is {lat.pitch:.2f} px but the optics give {pitch0:.2f} px; "
            "fix mla.pitch_um or sensor.pixel_um (binning?) in the optics file"
        )

    # 2. optical axis from the brightness pattern of all EIs
    xy_all = _all_cells(lat, img.shape)
    b_all = _ei_brightness(img, xy_all, r_ei, _INNER["white"])
    um_per_px = optics.pitch_um / lat.pitch
    r_pupil = optics.pupil_radius_mla_um
    r_src = optics.sigma * r_pupil
    if kind == "auto":
        kind = _decide_kind(img, b_all, fits, r_ei, optics)
    if _INNER[kind] != _INNER["white"]:
        b_all = _ei_brightness(img, xy_all, r_ei, _INNER[kind])
    if kind == "white":
        axis, axis_rms, axis_sig, par = _fit_axis(xy_all, b_all, r_pupil, um_per_px, optics, tilt=True)
        what = f"the objective pupil (NA {optics.na})"
    else:
        if r_src <= 0:
            raise SsdpcError(
                "condenser_na is 0, so a flat/sample frame cannot locate the optical axis; "
                "calibrate on a white frame taken with the condenser fully open"
            )
        axis, axis_rms, axis_sig, par = _fit_axis(xy_all, b_all, r_src, um_per_px, optics, tilt=False)
        what = f"the condenser disk (condenser_na {optics.condenser_na})"
    if axis_rms > MAX_AXIS_RMS or not axis_sig < 0.5:
        raise SsdpcError(
            f"elemental-image brightness does not match {what} (rms {100 * axis_rms:.1f}%, "
            f"axis ±{axis_sig:.2g} px); check objective NA, fourier_lens_mm and condenser_na in the "
            "optics, or calibrate on a white frame taken with the condenser fully open"
        )
    if kind != "white":
        n_lit = int(np.count_nonzero(b_all - par[3] > 0.05 * par[2]))
        warnings.warn(
            f"{kind} frame (σ = {optics.sigma:.2f}, {n_lit} lit lenslets): the optical axis comes from "
            "their brightness pattern and is good to about 0.5 px; for 0.05 px calibrate on a white "
            "frame taken with the condenser fully open",
            SsdpcWarning,
            stacklevel=2,
        )

    grid = _make_grid(lat, axis, optics)
    lens = grid.lenslets(optics)
    centres = grid.lattice_px([ln.row for ln in lens], [ln.col for ln in lens]).reshape(-1, 2)
    rel = (_ei_brightness(img, centres, r_ei, _INNER[kind]) - par[3]) / par[2]
    if r_ei > 0.5 * lat.pitch + 2:
        warnings.warn(
            f"EIs overlap (radius {r_ei:.1f} px > half pitch {0.5 * lat.pitch:.1f} px); close the field iris a little",
            SsdpcWarning,
            stacklevel=2,
        )
    return Calibration(
        grid=grid,
        ei_radius_px=r_ei,
        optics=optics,
        frame_shape=tuple(img.shape),
        lenslets=lens,
        centres_px=centres,
        brightness=rel,
        residual_px=rms,
        axis_rms=axis_rms,
        kind=kind,
        n_fitted=len(fits),
    )


def _decide_kind(img, b, fits, r_ei, optics):
    """White if about as many EIs are lit as lenslets lie in the pupil, else flat/sample."""
    ok = np.isfinite(b)
    bb = b[ok] - np.percentile(b[ok], 5)
    n_lit = int(np.count_nonzero(bb > 0.25 * bb.max()))
    n_pupil = sum(1 for ln in optics.lenslets() if ln.fraction >= 0.25)
    if n_lit >= 0.6 * n_pupil:
        return "white"
    return "sample" if _looks_like_sample(img, fits[:, :2], r_ei) else "flat"


def _make_grid(lat, axis, optics) -> Grid:
    """Grid whose reference vertex is the lattice vertex nearest the optical axis."""
    t = lat.index(axis) + 0.5  # axis in vertex units (vertex of cell n at n − ½)
    shift = np.rint(t)
    vertex = lat.centres(shift - 0.5)
    return Grid(
        xy_pair(axis),
        xy_pair(vertex),
        float(lat.pitch),
        float(lat.theta_deg),
        optics.flip_x,
        optics.flip_y,
    )


# ---------------------------------------------------------------- overlay
def overlay_png(frame, calibration: Calibration, path, *, dpi: int = 110) -> Path:
    """PNG of the frame with the detected EI circles, (row, col) labels and the optical
    axis (red +), cropped to the lenslets in the pupil. Written atomically."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    label_box = dict(boxstyle="round,pad=0.15", fc="black", alpha=0.6, lw=0)
    img = _validated(frame)
    cal = calibration
    g = cal.grid
    fig = Figure(figsize=(8, 8))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    lo, hi = np.percentile(img, [1, 99.8])
    ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
    c = cal.centres_px
    for ln, (cx, cy) in zip(cal.lenslets, c):
        col = "lime" if ln.fraction >= 0.5 else "orange"
        ax.add_patch(Circle((cx, cy), cal.ei_radius_px, fill=False, color=col, lw=0.8))
        ax.plot(cx, cy, ".", color=col, ms=2)
        ax.text(
            cx,
            cy - 0.35 * cal.ei_radius_px,
            f"({ln.row},{ln.col})",
            color=col,
            ha="center",
            va="center",
            fontsize=7,
            bbox=label_box,
        )
    ax.plot(*g.axis_px, "r+", ms=18, mew=2)
    r_pupil = cal.optics.pupil_radius_mla_um / cal.optics.pitch_um * g.pitch_px
    ax.add_patch(Circle(g.axis_px, r_pupil, fill=False, color="red", lw=0.8, ls="--"))
    m = cal.ei_radius_px * 1.3
    ax.set_xlim(min(c[:, 0].min(), g.axis_px[0] - r_pupil) - m, max(c[:, 0].max(), g.axis_px[0] + r_pupil) + m)
    ax.set_ylim(max(c[:, 1].max(), g.axis_px[1] + r_pupil) + m, min(c[:, 1].min(), g.axis_px[1] - r_pupil) - m)
    ax.set_title(
        f"{cal.kind} frame: axis ({g.axis_px[0]:.2f}, {g.axis_px[1]:.2f}) px, pitch {g.pitch_px:.3f} px, "
        f"rotation {g.rotation_deg:+.3f}°\nlattice rms {cal.residual_px:.3f} px; green: ≥50% inside pupil, "
        "orange: edge; red: optical axis and pupil",
        fontsize=9,
    )
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    fig.tight_layout()
    path = Path(path)
    with atomic_write(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    return path


# ------------------------------------------------------------ EI extraction
def _view_geometry(calibration: Calibration, size):
    """Object-pixel grid of the views and the sensor step per view pixel."""
    cal = calibration
    step = cal.grid.pitch_px / cal.optics.pitch_px  # sensor px per object pixel (1 at nominal pitch)
    if size is None:
        half = int(math.floor(cal.ei_radius_px / step))
        h = w = 2 * half + 1
    else:
        h, w = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))  # type: ignore[arg-type]
        if h < 1 or w < 1:
            raise SsdpcError(f"view size must be positive, got {size}")
    px = cal.optics.object_pixel_um
    ii = np.arange(h) - (h - 1) / 2
    jj = np.arange(w) - (w - 1) / 2
    return ii, jj, step, px


def extract_views(frame, calibration: Calibration, size=None, *, order: int = 1) -> Views:
    """Stack of EIs (K, h, w) float32, resampled upright on the object grid.

    View pixel (i, j) of lenslet k samples the sensor at
    ``centre_k + matrix @ (j − j0, i − i0) * step`` (``Grid.object_to_sensor``), so the
    rotation/flip of the camera is undone and an in-focus object point at (x, y) µm
    lands at view pixel (x, y) / object_pixel_um from the centre.
    """
    cal = calibration
    img = cal.check_frame(frame)
    ii, jj, step, px = _view_geometry(cal, size)
    A = cal.grid.matrix
    J, I = np.meshgrid(jj, ii)
    off = np.stack([J.ravel(), I.ravel()], 1) @ A.T * step  # (h*w, 2) sensor (x, y)
    c = np.asarray(cal.centres_px, float)
    xs = c[:, None, 0] + off[None, :, 0]
    ys = c[:, None, 1] + off[None, :, 1]
    data = ndimage.map_coordinates(
        img, [ys.ravel(), xs.ravel()], order=order, mode="constant", cval=0.0, prefilter=order > 1
    )
    data = data.reshape(len(c), len(ii), len(jj)).astype(np.float32)
    mask = (J**2 + I**2) * step**2 <= cal.ei_radius_px**2
    return Views(
        data=data,
        lenslets=list(cal.lenslets),
        centres_px=c.copy(),
        x_um=jj * px,
        y_um=ii * px,
        mask=mask,
        pixel_um=px,
        frame_shape=(int(cal.frame_shape[0]), int(cal.frame_shape[1])),
    )


def insert_views(views: Views, calibration: Calibration, *, order: int = 1, fill: float = 0.0) -> np.ndarray:
    """Inverse of :func:`extract_views`: paint each view back inside its iris disk on the
    sensor (float32 frame of the calibration's shape; ``fill`` elsewhere)."""
    cal = calibration
    H, W = cal.frame_shape
    out = np.full((H, W), fill, np.float32)
    step = cal.grid.pitch_px / cal.optics.pitch_px
    Ainv = np.linalg.inv(cal.grid.matrix)
    h, w = views.data.shape[1:]
    r = cal.ei_radius_px
    for k, (cx, cy) in enumerate(views.centres_px):
        x0, x1 = max(int(math.floor(cx - r)), 0), min(int(math.ceil(cx + r)) + 1, W)
        y0, y1 = max(int(math.floor(cy - r)), 0), min(int(math.ceil(cy + r)) + 1, H)
        if x0 >= x1 or y0 >= y1:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1].astype(float)
        inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
        d = np.stack([xx[inside] - cx, yy[inside] - cy], 1) @ Ainv.T / step  # view pixel offsets (j, i)
        vals = ndimage.map_coordinates(
            views.data[k],
            [d[:, 1] + (h - 1) / 2, d[:, 0] + (w - 1) / 2],
            order=order,
            mode="constant",
            cval=fill,
            prefilter=order > 1,
        )
        sub = out[y0:y1, x0:x1]
        sub[inside] = vals
    return out
