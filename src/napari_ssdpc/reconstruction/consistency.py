"""Cross-checks of a frame against the optics, the calibration and the flat, from the data themselves.

A frame can be a valid image and still disagree with what it is reconstructed with; each such
disagreement gave wrong numbers with exit 0 (docs/reliability.md). Measured on every frame and flat
(:class:`~napari_ssdpc.reconstruction.contrast.ViewContrast`), so in the CLI, the API and napari alike:

- the condenser NA its lenslets' light shows, against the optics' (paper Eq. 2: a lenslet's direct
  light is the overlap of the condenser disk and its sub-aperture);
- where its elemental images sit, against where the calibration puts them;
- its exposure against the flat's (normalised and reported, not refused).
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import NamedTuple

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import cpu
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics.pupil import Pupil
from napari_ssdpc.settings.lenslets import circle_overlap_fraction

__all__ = [
    "ApparentNA",
    "EI_SHIFT_TOLERANCE_PX",
    "EXPOSURE_TOLERANCE",
    "MAX_EI_SHIFT_PX",
    "MISFIT_FLOOR",
    "NA_EXCESS",
    "NA_EXCESS_LIGHT",
    "NA_RATIO",
    "NA_RATIO_FLAT",
    "NA_WARN",
    "NA_WARN_LIGHT",
    "apparent_condenser_na",
    "check_condenser_na",
    "check_ei_shift",
    "check_exposure",
    "check_lit_lenslets",
    "ei_shift_px",
    "ei_templates",
    "warn_condenser_na",
]


#: The smallest misfit a fit of the lenslets' levels is held to (the brightest lenslet's light
#: squared): the noise of the median levels of a flat.
MISFIT_FLOOR = 1e-4


class ApparentNA(NamedTuple):
    """The condenser NA a frame's lenslets look lit at (:func:`apparent_condenser_na`)."""

    na: float  #: the best-fitting condenser NA
    excess: float  #: the optics' NA's misfit over the best's, in units of ``misfit``
    misfit: float  #: the best NA's misfit (at least MISFIT_FLOOR), the brightest lenslet's light squared


def apparent_condenser_na(levels, lenslets, optics) -> ApparentNA:
    """The condenser NA a frame's lenslet levels look recorded at, and how clearly the optics' NA is
    excluded.

    A lenslet's direct light is the area of the condenser disk |u| ≤ NA_c/λ inside its sub-aperture
    (paper Eq. 2): the overlap of two circles. Over the lenslets wholly inside the objective's
    pupil, the measured levels (scaled to their largest) are fitted by the overlaps times the
    best scale (least squares; the lamp's brightness is unknown); the NA is searched on a 0.005 grid
    refined to 0.0005 about the best. Where several NAs light the same lenslets alike (near a fully
    open condenser every inner lenslet is lit whole), the fit cannot tell them apart, and the
    misfit the best NA leaves (lenslets that transmit unequally, vignetting, noise) says how far
    others are from it: the optics' NA is excluded only where it fits worse by more than that.

    Parameters
    ----------
    levels : ndarray, (K,)
        Every lenslet's median light above the dark level, camera units.
    lenslets : list of Lenslet
        The calibration's lenslets (their ``u`` and ``fraction``).
    optics : Optics
        Wavelength, sub-aperture radius, objective and condenser NA.

    Returns
    -------
    ApparentNA
        ``na``, the best-fitting condenser NA; ``excess``, the misfit at the optics' NA minus the
        best, over the best's own misfit ``misfit`` (at least :data:`MISFIT_FLOOR`): above 1 the
        optics' NA explains the levels clearly worse than the best one.
    """
    inner = np.array([ln.fraction >= 0.999 for ln in lenslets])
    u_k, rho_k, _ = Pupil.of(optics).lenslet_arrays(lenslets)  # each lenslet's own sub-aperture
    d, rho = np.hypot(*(u_k[inner] - optics.source_centre).T), rho_k[inner]  # from the condenser's centre
    lv = np.clip(np.asarray(levels, float)[inner], 0, None)
    lv = lv / max(lv.max(), 1e-30)
    nas, overlaps = _overlaps(tuple(d), tuple(rho), float(optics.wavelength_um), float(optics.na))

    def misfit(m):  # Σ (lv − s m)² at the best scale s, for each row of m
        return lv @ lv - (m @ lv) ** 2 / np.maximum(np.einsum("ij,ij->i", m, m), 1e-30)

    coarse = np.arange(0, len(nas), 10)  # a 0.005 grid
    k0 = int(coarse[int(np.argmin(misfit(overlaps[coarse])))])
    fine = np.arange(max(0, k0 - 10), min(len(nas) - 1, k0 + 10) + 1)  # refined to 0.0005 about the best
    err = misfit(overlaps[fine])
    best = int(np.argmin(err))
    floor = max(float(err[best]), MISFIT_FLOOR)
    m_optics = circle_overlap_fraction(d, rho, optics.condenser_na / optics.wavelength_um)
    excess = (float(misfit(m_optics[None])[0]) - float(err[best])) / floor
    return ApparentNA(round(float(nas[fine[best]]), 4), excess, floor)


@functools.lru_cache(maxsize=16)
def _overlaps(d: tuple, radius: tuple, wavelength_um: float, na_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Condenser NAs 0.01..na_max every 0.0005, and each lenslet's lit fraction at each: (N,), (N, K).
    The same for every frame of a calibration: computed once."""
    nas = 0.01 + 0.0005 * np.arange(int(np.floor((na_max - 0.01) / 0.0005 + 1e-6)) + 1)
    return nas, np.array([circle_overlap_fraction(np.asarray(d), np.asarray(radius), na / wavelength_um) for na in nas])


def check_lit_lenslets(lenslets, optics, name: str = "flat frame") -> None:
    """Refuse lenslets lit on the flat whose sub-aperture the condenser disk does not reach.

    A lenslet gets direct light only where its sub-aperture overlaps the condenser disk (paper
    Eq. 2). One that the flat shows lit although the overlap is empty sits where the calibration
    puts another lenslet: its centres were swapped or edited (or the condenser NA is wrong).

    Parameters
    ----------
    lenslets : list of Lenslet
        The lenslets lit on the flat.
    optics : Optics
    name : str
        For the message.
    """
    u_k, rho_k, _ = Pupil.of(optics).lenslet_arrays(lenslets)  # each lenslet's own sub-aperture
    model = circle_overlap_fraction(np.hypot(*(u_k - optics.source_centre).T), rho_k, optics.source_radius)
    dark = [ln for ln, m in zip(lenslets, model) if m <= 0]
    if dark:
        ln = dark[0]
        raise SsdpcError(
            f"{name}: {len(dark)} lenslet(s) are lit (e.g. row {ln.row}, col {ln.col}) whose sub-aperture the "
            f"condenser disk (NA {optics.condenser_na:g}) does not reach: the calibration's lenslet centres were "
            "swapped or edited, or condenser_na is not the flat's; recalibrate on a white frame (`ssdpc calibrate`) "
            "or set condenser_na"
        )


#: A frame is refused as lit at another condenser NA when the optics' NA fits its lenslets' light
#: clearly worse than the best NA (the excess of :func:`apparent_condenser_na` above ``NA_EXCESS``)
#: and the two NAs differ by more than ``NA_RATIO_FLAT`` for a flat (a bead's peak Δn came out 21 %
#: low with a flat and frame at 0.315 reconstructed as 0.3, and 44 % low at 0.33) or ``NA_RATIO``
#: for a raw frame. A raw frame's sample moves its lenslets' light: a smooth modulation of 5-30 %
#: moved the fit of frames at 0.1 by up to 46 % with an excess up to 6.5 (at 0.3 by 1 %), so a raw
#: frame is also held to an absolute excess, ``NA_EXCESS_LIGHT`` (the brightest lenslet's light
#: squared; those modulations reached 0.009): frames at 0.1 read as 0.2 or 0.3 exceed it 3-10 times.
NA_EXCESS, NA_RATIO_FLAT, NA_RATIO, NA_EXCESS_LIGHT = 5.0, 1.1, 1.3, 0.25


def check_condenser_na(seen: ApparentNA, optics, name: str, fix: str, flat: bool = False) -> None:
    """Refuse a frame lit at another condenser NA than the optics say.

    Parameters
    ----------
    seen : ApparentNA
        :func:`apparent_condenser_na` of the frame.
    optics : Optics
    name, fix : str
        For the message.
    flat : bool
        Whether the frame is a flat (no sample: held to :data:`NA_RATIO_FLAT`).
    """
    na_seen, excess, misfit = seen
    na = float(optics.condenser_na)
    ratio = NA_RATIO_FLAT if flat else NA_RATIO
    clear = excess > NA_EXCESS and (flat or excess * misfit > NA_EXCESS_LIGHT)
    if clear and not 1 / ratio <= na_seen / na <= ratio:
        seen_text = f"about {na_seen:.3f}" if na_seen < 0.85 * optics.na else f"{na_seen:.3f} or more (open)"
        raise SsdpcError(
            f"{name}: its lenslets are lit as by a condenser NA of {seen_text}, but the optics say {na:g}; {fix}"
        )


#: A flat is reported (a warning, the result kept) when its lenslets' light fits an NA that differs
#: from the optics' by more than ``NA_WARN`` (relative) and fits better (excess above 1: the optics'
#: NA leaves twice the best one's misfit). On flats at 0.3 with lenslets transmitting 2-5 % unequally
#: the fit stayed within 0.3-0.8 % of the truth (excess at most 0.6). A raw frame (reported where no
#: flat is given) must also misfit by ``NA_WARN_LIGHT`` of the brightest lenslet's light squared,
#: above what a sample's modulation gave (0.009, see :data:`NA_EXCESS`); a frame at 0.315 read as
#: 0.3 misfits by about 0.07.
NA_WARN, NA_WARN_LIGHT = 0.03, 0.03


def warn_condenser_na(seen: ApparentNA, optics, name: str, flat: bool = True) -> None:
    """Report a frame lit at a condenser NA a few per cent off the optics' (where
    :func:`check_condenser_na` does not refuse it).

    Parameters
    ----------
    seen : ApparentNA
        :func:`apparent_condenser_na` of the frame.
    optics : Optics
    name : str
        For the message.
    flat : bool
        Whether the frame is a flat (else a raw frame, held to :data:`NA_WARN_LIGHT` too).
    """
    na_seen, excess, misfit = seen
    na = float(optics.condenser_na)
    clear = excess > 1 and (flat or excess * misfit > NA_WARN_LIGHT)
    if clear and abs(na_seen / na - 1) > NA_WARN:
        warnings.warn(
            f"{name}: its lenslets are lit as by a condenser NA of {na_seen:.3f}, the optics say {na:g}: Δn depends "
            f"on it through the transfer functions (5 % off moved a bead's peak Δn by 21 %); set condenser_na to "
            f"{na_seen:.3f} if the condenser was there, or measure its NA and centre on the flat with `ssdpc "
            "fit-optics --calibration CAL --flat FLAT -o FITTED.json`",
            SsdpcWarning,
            stacklevel=4,
        )


#: Largest shift of the elemental images from the calibration that is measured, and the shift
#: beyond which a frame is refused (px).
MAX_EI_SHIFT_PX, EI_SHIFT_TOLERANCE_PX = 16, 1.5


def ei_templates(cal, lit) -> tuple[int, list]:
    """The spectra of the calibrated disks of the lit lenslets, for :func:`ei_shift_px`.

    Parameters
    ----------
    cal : Calibration
    lit : ndarray of int
        The lenslets lit by direct light.

    Returns
    -------
    h : int
        Half-width of the windows, px (the radius plus the largest shift measured).
    items : list of (int, int, ndarray)
        Per lenslet on the sensor: the pixel nearest its centre (x, y) and the conjugate spectrum
        (rfft2, zero-padded to a fast size) of its zero-mean disk on a window of ``2 h + 1`` px.
    """
    r, h = float(cal.ei_radius_px), int(math.ceil(cal.ei_radius_px)) + MAX_EI_SHIFT_PX
    yy, xx = np.mgrid[-h : h + 1, -h : h + 1].astype(float)
    out = []
    for k in lit:
        cx, cy = (float(c) for c in cal.centres_px[k])
        ix, iy = int(round(cx)), int(round(cy))
        if iy - h < 0 or ix - h < 0 or iy + h >= cal.frame_shape[0] or ix + h >= cal.frame_shape[1]:
            continue  # at the sensor's edge
        disk = (np.hypot(xx - (cx - ix), yy - (cy - iy)) <= r).astype(float)
        n = sfft.next_fast_len(2 * h + 1, real=True)
        out.append((ix, iy, np.conj(cpu().rfft2(disk - disk.mean(), s=(n, n)))))
    return h, out


def ei_shift_px(img, templates) -> tuple[float, float]:
    """How far a frame's elemental images sit from where the calibration puts them, px.

    Each lit lenslet's elemental image is a disk of radius ``ei_radius_px`` (the field stop's
    image). Around every calibrated centre the frame is cross-correlated with that disk; the
    correlations of all lit lenslets are added (a moved camera or array shifts them all alike) and
    the peak, refined by a parabola, is the shift.

    Parameters
    ----------
    img : ndarray, (H, W)
        The frame, camera units.
    templates : (int, list)
        :func:`ei_templates` of the calibration.

    Returns
    -------
    (float, float)
        (dx, dy) of the images from the calibration, px.
    """
    h, items = templates
    if not items:
        return 0.0, 0.0
    n = items[0][2].shape[0]
    acc_hat = np.zeros_like(items[0][2])
    for ix, iy, spec in items:  # the correlations are added in Fourier space: one inverse transform
        win = np.asarray(img[iy - h : iy + h + 1, ix - h : ix + h + 1], float)
        w = win - win.mean()
        acc_hat += cpu().rfft2(w, s=(n, n)) * spec / max(float(w.std()), 1e-12)
    acc = cpu().irfft2(acc_hat, s=(n, n))
    m = MAX_EI_SHIFT_PX
    near = np.roll(acc, (m, m), axis=(0, 1))[: 2 * m + 1, : 2 * m + 1]  # shifts −m..m
    py, px = np.unravel_index(int(np.argmax(near)), near.shape)
    out = []
    for peak, line in ((px, near[py]), (py, near[:, px])):
        sub = 0.0
        if 0 < peak < len(line) - 1:
            a, b, d = line[peak - 1], line[peak], line[peak + 1]
            den = a - 2 * b + d
            sub = 0.5 * (a - d) / den if den < 0 else 0.0
        out.append(peak - m + sub)
    return out[0], out[1]


def check_ei_shift(shift, name: str) -> None:
    """Refuse a frame whose elemental images are not where the calibration puts them.

    Parameters
    ----------
    shift : (float, float)
        :func:`ei_shift_px` of the frame.
    name : str
        For the message.
    """
    dx, dy = shift
    if math.hypot(dx, dy) > EI_SHIFT_TOLERANCE_PX:
        raise SsdpcError(
            f"{name}: its elemental images sit {dx:+.1f}, {dy:+.1f} px (x, y) from where the calibration puts them: "
            "the camera or the array moved, or the calibration was edited; recalibrate on a white frame "
            "recorded in this position"
        )


#: A frame brighter or dimmer than its flat by more than this (relative) is reported.
EXPOSURE_TOLERANCE = 0.1


def check_exposure(exposure: float, name: str) -> None:
    """Report a frame lit differently from its flat (its views are normalised to the flat's level).

    Parameters
    ----------
    exposure : float
        The frame's background light over the flat's.
    name : str
        For the message.
    """
    if abs(exposure - 1) > EXPOSURE_TOLERANCE:
        factor = f"{exposure:.2f}" if exposure >= 0.1 else f"{exposure:.2g}"  # a float frame of 0..1: 0.00024
        warnings.warn(
            f"{name} is {factor} x as bright as the flat frame (exposure time, lamp or gain changed): its views "
            "were normalised to the flat's level (metadata exposure_ratio); record frame and flat alike",
            SsdpcWarning,
            stacklevel=3,
        )
