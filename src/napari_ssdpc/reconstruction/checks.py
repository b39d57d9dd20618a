"""Checks of the inputs and the result, made once where the core meets them.

The :class:`~napari_ssdpc.reconstruction.reconstructor.Reconstructor` runs them for the CLI,
napari, the series runner and the Python API alike:

- :func:`check_optics_match`: the optics in use against the calibration's (every field that
  changes the numbers: :data:`OPTICS_FIELDS`) and against the lattice pitch measured on the
  white frame; :func:`optics_in_use` adds the calibration's aberrations to optics that have none.
- :func:`~napari_ssdpc.reconstruction.memory.check_memory` (its own module): an estimate of the
  operators and outputs against the free memory.
- :func:`check_flat` and :func:`check_frame_light`: a flat or raw frame without light, all
  saturated, inverted, noise only or white (condenser open) is refused with what is wrong;
  they read the per-lenslet light of views that are extracted once (:mod:`.contrast`).
- :func:`check_result`: non-finite or unphysical volumes are refused before writing.
"""

from __future__ import annotations

import numpy as np

from napari_ssdpc.calibration.saturation import FULL_SCALE_CODES
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction import consistency
from napari_ssdpc.settings.parts import PART_KEYS

__all__ = [
    "MAX_DELTA_N",
    "OPTICS_FIELDS",
    "check_constant",
    "check_flat",
    "check_frame_light",
    "check_optics_match",
    "optics_in_use",
    "check_result",
    "check_saturated",
    "dark_pixel_index",
    "dark_pixels",
]

#: |Δn| beyond this is no biological or polymer sample in any medium: a wrong input or setting.
MAX_DELTA_N = 0.5


#: Every optics field that changes the numbers, as (what, attribute, unit, largest relative
#: difference; None: must be equal). The condenser NA is left out: it is measured on every frame
#: and flat (:mod:`.consistency`), and a calibration on a white frame may name another; the field
#: stop (``iris_radius_um``) too: the calibration measures the elemental images' radius itself.
OPTICS_FIELDS = (
    ("objective magnification", "magnification", "x", 0.01),
    ("objective NA", "na", "", 0.01),
    ("tube-lens focal length", "tube_lens_mm", " mm", 0.01),
    ("Fourier-lens focal length", "fourier_lens_mm", " mm", 0.01),
    ("MLA pitch", "pitch_um", " µm", 0.01),
    ("MLA focal length", "mla_focal_length_mm", " mm", 0.01),
    ("lenslet radius", "lenslet_radius_um", " µm", 0.01),
    ("camera pixel size", "pixel_um", " µm", 0.01),
    ("wavelength", "wavelength_um", " µm", 0.01),
    ("medium index", "medium_index", "", 0.0005),  # Δn of cells is ~0.02: RI labelled 0.01 off is wrong
    ("camera's x mirroring", "flip_x", "", None),
    ("camera's y mirroring", "flip_y", "", None),
)


def check_optics_match(optics, cal, source: str = "--optics") -> None:
    """Refuse optics that do not describe the instrument the calibration was made on.

    Parameters
    ----------
    optics : Optics
        The optics in use.
    cal : Calibration
        The calibration (its optics and its measured lattice pitch).
    source : str
        Where the optics come from, for the message.

    Raises
    ------
    SsdpcError
        A field of :data:`OPTICS_FIELDS` differs beyond its tolerance (1 %; the medium index
        0.05 %; a mirroring at all), the array lattice (square or hex) differs, or the measured
        pitch differs from the optics' by more than 3 %.
    """
    for what, attr, unit, tol in OPTICS_FIELDS:
        a, b = getattr(optics, attr), getattr(cal.optics, attr)
        if (a != b) if tol is None else abs(float(a) - float(b)) > tol * abs(float(b)):
            va, vb = (str(a).lower(), str(b).lower()) if tol is None else (f"{a:g}{unit}", f"{b:g}{unit}")
            if attr == "medium_index" and "pupil" in cal.optics_fit:
                raise SsdpcError(
                    f"the optics ({source}) give a medium index of {va}, the calibration's objective aberration "
                    f"was fitted to beads in {vb} (a spherical aberration changes with the medium): fit the "
                    f"optics to beads in this medium (`ssdpc fit-optics BEADS.tif --calibration CAL --flat FLAT "
                    f"--medium-index {va} -o FITTED.json`), or give the optics the calibration was made with"
                )
            raise SsdpcError(
                f"the optics ({source}) and the calibration disagree on the {what} ({_key(attr)}: {va} vs "
                f"{vb} in the calibration); give the optics the calibration was made with, or recalibrate with "
                "these (`ssdpc calibrate WHITE.tif --optics ...`)"
            )
    if optics.grid != cal.grid.lattice:
        raise SsdpcError(
            f"the optics ({source}) give a {optics.grid} array (mla.grid) but the calibration was made for a "
            f"{cal.grid.lattice} one; set mla.grid: {cal.grid.lattice} or recalibrate with these optics"
        )
    measured, expected = float(cal.grid.pitch_px), float(optics.pitch_px)
    if abs(measured - expected) > 0.03 * expected:
        raise SsdpcError(
            f"the calibration's lattice pitch {measured:.2f} px differs from the optics' {expected:.2f} px by "
            f"{100 * abs(measured / expected - 1):.0f}%: the calibration or its optics were edited or belong to "
            "another instrument; recalibrate on a white frame"
        )


def optics_in_use(optics, cal, source: str = "--optics"):
    """The optics a reconstruction uses: the given ones, checked against the calibration's
    (:func:`check_optics_match`), with the calibration's aberrations where the given optics have none
    and its condenser NA where `ssdpc fit-optics` measured it and the given optics still name the NA
    it corrected (a calibration with fitted optics carries the instrument as it is,
    docs/aberrations.md; optics that name another NA are a new condenser setting and are kept).

    Parameters
    ----------
    optics : Optics
        The optics given (file, widget or run configuration).
    cal : Calibration
    source : str
        Where the optics come from, for the message.

    Returns
    -------
    Optics

    Raises
    ------
    SsdpcError
        As :func:`check_optics_match`, or both give aberrations and they differ.
    """
    check_optics_match(optics, cal, source)
    fitted = cal.optics_fit.get("condenser", {})
    if fitted and optics.condenser_na == fitted.get("na_given"):  # the NA the fit corrected, not a new setting
        optics = optics.replace(condenser_na=cal.optics.condenser_na)  # measured on the user's flat frame
    mine, theirs = optics.aberrations, cal.optics.aberrations
    if theirs.is_nominal or mine == theirs:
        return optics
    if mine.is_nominal:
        return optics.replace(aberrations=theirs)
    raise SsdpcError(
        f"the optics ({source}) and the calibration give different aberrations ({mine.summary()} vs "
        f"{theirs.summary()} in the calibration); remove the optics' aberrations section to use the calibration's"
    )


def _key(attr: str) -> str:
    """The optics file's key of a flat attribute (``objective.na`` for ``na``)."""
    return ".".join(PART_KEYS[attr]) if attr in PART_KEYS else attr


def dark_pixel_index(cal, step: int = 8) -> np.ndarray:
    """Flat indices of a sparse sample of the pixels farther than 1.2 EI radii from every lenslet centre.

    Parameters
    ----------
    cal : Calibration
        Its frame shape, lenslet centres and EI radius.
    step : int
        Sampling step, px (a sparse sample is plenty for a median).

    Returns
    -------
    ndarray of int, (N,)
        Indices into the raveled (H, W) frame (empty where the EIs fill the frame).
    """
    H, W = (int(v) for v in cal.frame_shape)
    yy, xx = np.mgrid[0:H:step, 0:W:step]
    far = np.ones(yy.shape, bool)
    r2 = (1.2 * cal.ei_radius_px) ** 2
    for cx, cy in cal.centres_px:
        far &= (xx - cx) ** 2 + (yy - cy) ** 2 > r2
    return yy[far] * W + xx[far]


def dark_pixels(img, cal, step: int = 8) -> np.ndarray:
    """The values of the pixels of :func:`dark_pixel_index`.

    Parameters
    ----------
    img : ndarray, (H, W)
        Camera units (the calibration's frame shape).
    cal : Calibration
    step : int
        Sampling step, px.

    Returns
    -------
    ndarray, (N,)
    """
    return np.asarray(img).ravel()[dark_pixel_index(cal, step)]


def check_constant(img, name: str) -> None:
    """Refuse a frame whose pixels all hold one value (no light, saturated, or no image).

    Parameters
    ----------
    img : ndarray, (H, W)
        Camera units.
    name : str
        For the message.
    """
    lo, hi = float(np.min(img)), float(np.max(img))
    if hi > lo:
        return
    if hi in FULL_SCALE_CODES:
        raise SsdpcError(
            f"{name}: every pixel is {hi:g}, the top of the camera's range: the camera was saturated; "
            "shorten the exposure or dim the lamp and record it again"
        )
    if hi == 0:
        raise SsdpcError(f"{name}: every pixel is 0: no light reached the camera; check the lamp and the shutter")
    raise SsdpcError(f"{name}: every pixel is {hi:g}: there is no image in it; check the camera and the file")


def check_saturated(raw, name: str) -> float:
    """Refuse a frame with more than 20 % of its pixels saturated; warn above 0.01 %.

    Parameters
    ----------
    raw : ndarray, (H, W)
        As read (its dtype gives the camera's full scale).
    name : str
        For the messages.

    Returns
    -------
    float
        The saturated fraction.
    """
    from napari_ssdpc.calibration.saturation import saturated_fraction, warn_saturation

    frac = saturated_fraction(raw)
    warn_saturation(raw, name, fraction=frac)
    if frac > 0.2:
        raise SsdpcError(f"{name}: {100 * frac:.0f}% of the pixels are saturated; shorten the exposure or dim the lamp")
    return frac


def check_flat(levels, noise: float, optics, name: str = "flat frame", lenslets=None) -> float | None:
    """Refuse a flat frame without light, recorded at another condenser NA, or with the condenser
    open (white); report one a few per cent off the optics' condenser NA.

    Parameters
    ----------
    levels : ndarray, (K,)
        Every lenslet's median light above the dark level, camera units.
    noise : float
        Noise of the dark pixels, camera units.
    optics : Optics
        The optics in use (its condenser NA).
    name : str
        For the message.
    lenslets : list of Lenslet, optional
        All the calibration's lenslets: the condenser NA the flat looks lit at is checked too.

    Returns
    -------
    float or None
        The condenser NA the flat's lenslets look lit at (None without ``lenslets``).
    """
    top = float(np.nanmax(levels))
    if not top > 5 * noise:
        raise SsdpcError(
            f"{name}: no light in the elemental images (brightest {top:.3g} above the dark level, noise {noise:.3g}); "
            "record the flat with the lamp on, the condenser at the raw frames' NA and no sample"
        )
    fix = "record the flat at the condenser NA of the raw frames"
    fix_both = fix + " (or set condenser_na to the NA of both)"
    return _lighting(levels, top, lenslets, optics, name, fix_both, fix, flat=True, warn=True)


def _lighting(
    levels, top: float, lenslets, optics, name: str, fix: str, white_fix: str, flat: bool, warn: bool
) -> float | None:
    """The condenser-NA checks of :mod:`.consistency` and :func:`_white` on a frame's levels; the NA
    they look lit at (None without ``lenslets``).

    Near a fully open condenser every lenslet inside the pupil is lit whole and the fit cannot
    tell the NAs there apart: it gives the lowest that lights them all, and the optics' NA fits as
    well unless it is clearly lower. Such a frame is first checked for a white frame (named as one);
    a frame whose NA is measurable is first checked for its NA (named with the number). A flat (no
    sample) is held to the NA closely; a raw frame, whose sample moves its lenslets' light, only
    refused far off. With ``warn``, an NA a few per cent off is reported (the flat; a raw frame
    when no flat is given).
    """
    seen = None if lenslets is None else consistency.apparent_condenser_na(levels, lenslets, optics)
    looks_open = seen is None or seen[0] >= 0.85 * optics.na
    if looks_open:
        _white(levels, top, optics, name, white_fix)
    if seen is not None:
        consistency.check_condenser_na(seen, optics, name, fix, flat)
        if warn:
            consistency.warn_condenser_na(seen, optics, name, flat)
    if not looks_open:
        _white(levels, top, optics, name, white_fix)
    return None if seen is None else seen[0]


def _white(levels, top: float, optics, name: str, fix: str) -> None:
    """Refuse a frame whose lenslets are evenly lit although the condenser NA lights only a few.

    With the condenser fully open (a white frame, for calibration) every lenslet is lit; at a
    condenser NA with sigma < 0.7 most lenslets see only scattered light.
    """
    lit = float(np.mean(levels >= 0.5 * top))
    expected = min(1.0, float(optics.sigma) ** 2)
    if expected < 0.5 and lit > expected + 0.4:
        raise SsdpcError(
            f"{name}: {100 * lit:.0f}% of the lenslets are evenly lit, as on a white frame (condenser fully open), "
            f"but the condenser NA {optics.condenser_na:g} lights about {100 * expected:.0f}%; {fix}"
        )


def check_frame_light(
    levels, noise: float, lit, expected, optics, name: str = "frame", lenslets=None, flat: bool = True
) -> None:
    """Refuse a raw frame without light in the lit lenslets' views, or unlike the flat.

    Parameters
    ----------
    levels : ndarray, (K,)
        Every lenslet's median light above the dark level, camera units.
    noise : float
        Noise of the dark pixels, camera units.
    lit : ndarray of int, (K_lit,)
        The lenslets that get direct light.
    expected : ndarray, (K_lit,)
        Their direct light on the flat (or the model's), any scale.
    optics : Optics
        The optics in use (its condenser NA).
    name : str
        For the message.
    lenslets : list of Lenslet, optional
        All the calibration's lenslets: the condenser NA the frame looks lit at is checked too.
    flat : bool
        Whether ``expected`` was measured on a flat frame (else it is the optics' model).
    """
    on = levels[lit]
    signal = float(np.median(on))
    fix = "set condenser_na to the NA the frames were recorded at (and record the flat at it)"
    if signal > 5 * noise:
        white_fix = "give a raw frame recorded at that condenser NA, not the white frame"
        _lighting(levels, signal, lenslets, optics, name, fix, white_fix, flat=False, warn=not flat)
    elif lenslets is not None and float(np.max(levels)) > 5 * noise:  # light, but not where the optics put it
        consistency.check_condenser_na(consistency.apparent_condenser_na(levels, lenslets, optics), optics, name, fix)
    if not signal > 5 * noise:
        raise SsdpcError(
            f"{name}: no light in the directly lit elemental images (median {signal:.3g} above the dark level, "
            f"noise {noise:.3g}): the lamp was off, the frame is inverted or noise only, or it comes from "
            "another instrument; give a raw light-field frame of this microscope"
        )
    ratio = on / np.maximum(np.asarray(expected, float), 1e-12)
    spread = float(np.std(ratio) / np.mean(ratio))
    if spread > 0.5:
        against = "the flat's" if flat else "the optics' model (no flat given)"
        raise SsdpcError(
            f"{name}: the lit lenslets' brightness differs from {against} by {100 * spread:.0f}% (rms): the frame "
            "does not look like this instrument's frames at this condenser NA; check the calibration (recalibrate "
            "on a white frame), the flat and condenser_na"
        )


def check_result(delta_n, optics, name: str = "volume") -> None:
    """Refuse a non-finite or unphysical Δn volume before it is written.

    Parameters
    ----------
    delta_n : numpy.ndarray
        Refractive-index difference to the medium.
    optics : Optics
        For the message (condenser NA).
    name : str
        For the message.
    """
    dn = np.asarray(delta_n)
    bad = int(dn.size - np.count_nonzero(np.isfinite(dn)))
    if bad:
        raise SsdpcError(
            f"the reconstructed {name} holds {bad} NaN/inf values; nothing was written. Check --dz and --alpha "
            "(finite, in range) and the flat frame"
        )
    peak = float(np.max(np.abs(dn))) if dn.size else 0.0
    if peak > MAX_DELTA_N:
        raise SsdpcError(
            f"the reconstructed {name} reaches |Δn| = {peak:.3g}, beyond any sample (±{MAX_DELTA_N}); nothing was "
            f"written. Likely the condenser NA of the optics ({optics.condenser_na:g}) is not the one the frames "
            "were recorded with, or --alpha is far too small"
        )
