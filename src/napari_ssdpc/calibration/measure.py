"""Lenslet-grid calibration: ``calibrate(frame, optics)``.

The optics are a prior (pitch, EI radius, pupil radius) and a consistency check;
everything else is measured on the frame:

1. EI disks (``disks``): a ring filter finds them, a robust circle through the rim
   points of each (notches, dust and sample content rejected as outliers) and a
   soft-disk rim fit give every EI its own sub-pixel centre and radius.
2. Lattice (``lattice_fit``, ``refine``): an affine lattice (pitch, rotation, unequal axes, shear)
   is fitted to those centres; it labels the lenslets and fills in the ones whose rim
   could not be measured. Each lenslet keeps its measured centre and its deviation from
   the lattice (a warning above 2 % of the pitch). Tolerances scale with the pitch.
3. Optical axis and kind of frame (``axis``): from the EI brightness pattern (the
   objective pupil on a white frame, the condenser disk on a flat or sample frame).
4. Table: (row, col), EI centre, a_k and u_k from the measured centre, the part of the
   lenslet inside the pupil, the halves of paper Eq. 5 and the brightness.
5. On a white frame, the views' focus (``view_focus``): the rims of the EIs nearest the axis
   against the stop's image through in-focus and defocused lenslets; views out of focus that the
   optics do not model are reported, naming `ssdpc fit-optics` (and again on every frame).

A user's rough EI positions (``guess``, e.g. from the napari Points layer) replace the
ring filter when detection fails. Coordinates: x = column, y = row,
pixel centres at integers.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from napari_ssdpc.calibration.axis import FULL_PUPIL, all_cells, decide_kind, ei_brightness, fit_axis, pupil_lenslets
from napari_ssdpc.calibration.disks import Candidates, Circle, find_disks, noise_sigma, rim_circle
from napari_ssdpc.calibration.frame import validated
from napari_ssdpc.calibration.lattice_fit import MIN_AFFINE, AffineLattice, assign
from napari_ssdpc.calibration.refine import OUTLIER, SMALL_EI_PX, all_rims, fit_lattice, outshone, refine_centres
from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.calibration.saturation import FULL_SCALE_CODES
from napari_ssdpc.calibration.view_focus import rim_defocus, rims_notice, rims_unmodelled
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics.geometry import mla_to_frequency
from napari_ssdpc.physics.lattice import Grid, xy_pair
from napari_ssdpc.settings.lenslets import Lenslet, circle_overlap_fraction, lattice_cell
from napari_ssdpc.settings.optics import Optics

__all__ = ["KINDS", "calibrate"]

KINDS = ("auto", "white", "flat", "sample")

PRIOR_TOLERANCE = 0.05  # measured pitch and EI radius may differ from the optics' by 5 %
DEVIATION_WARN = 0.02  # warn when a lenslet sits more than 2 % of the pitch off the lattice
MAX_LATTICE_RMS = 0.05  # rms of the EI centres about the lattice, as a fraction of the pitch
MAX_AXIS_RMS = 0.05  # rms of the brightness-pattern fit, relative to full brightness
FEW_LENSLETS = 20  # with fewer lit lenslets the illumination envelope is not fitted
MIN_DARK_CELLS = 4  # a white frame with fewer dark EIs on the sensor does not show the pupil's edge
# EI brightness is the mean inside this fraction of the EI radius: the centre, away from
# the diffraction-blurred rim, without a sample; nearly the whole EI with a sample, which
# moves light around inside the EI but mostly keeps it there.
_INNER = {"white": 0.5, "flat": 0.5, "sample": 0.85}


def _check_signal(raw, img):
    """Blank and saturated frames. Saturation counts pixels at the top code value of an
    integer frame (or a float frame whose maximum is 2^n - 1)."""
    lo, hi = float(img.min()), float(img.max())
    if hi - lo <= 0:
        raise SsdpcError(
            f"frame is blank (every pixel is {hi:g}); "
            "record a white frame with the lamp on and the condenser fully open"
        )
    if np.asarray(raw).dtype.kind in "ui" or hi in FULL_SCALE_CODES:
        bright = img > lo + 0.5 * (hi - lo)
        n_top = int(np.count_nonzero(img >= hi))
        if n_top > 50 and n_top > 5e-3 * np.count_nonzero(bright):
            raise SsdpcError(
                f"frame is saturated ({n_top} pixels at {hi:g}); "
                "shorten the exposure or dim the lamp and record it again"
            )


# ------------------------------------------------------------- step 1: EI disks
def _measure_disks(img, cand: Candidates, radius, pitch):
    """Robust rim circle of every candidate whose centre lies in the frame."""
    H, W = img.shape
    out: list[tuple[Circle, float]] = []
    for c, s in zip(cand.xy, cand.strength):
        circ = rim_circle(img, c, radius)
        if circ is None or circ.inlier_frac < 0.4:
            continue
        x, y = circ.centre
        if not (0 <= x <= W - 1 and 0 <= y <= H - 1) or abs(circ.radius / radius - 1) > 0.2:
            continue
        if any(math.hypot(x - q[0].centre[0], y - q[0].centre[1]) < 0.3 * pitch for q in out):
            continue
        out.append((circ, float(s)))
    return out


# ------------------------------------------------------------------ calibrate
def calibrate(frame, optics: Optics, *, kind: str = "auto", guess=None, axis=None) -> Calibration:
    """Measure the lenslet grid and the optical axis on one raw frame.

    Parameters
    ----------
    frame : array_like (H, W)
        Raw camera frame, any integer or float dtype (8-, 12-, 16-bit or float).
    optics : Optics
        The instrument: the prior for the pitch, EI radius and pupil.
    kind : {"auto", "white", "flat", "sample"}
        "white" (condenser fully open, σ = 1: the objective pupil edge gives the axis;
        the recommended input), "flat" or "sample" (the sample's condenser setting,
        σ < 1: the lit-lenslet pattern gives the axis, less precisely) or "auto"
        (decided from the lit pattern and the content of the EIs; the evidence is in
        ``Calibration.kind_evidence``).
    guess : array_like (N, 2), optional
        Rough EI centres (x, y) px, e.g. clicked in napari; they replace the automatic
        detection (within about a fifth of the EI radius is enough).
    axis : (float, float), optional
        The optical axis (x, y) px, when known from elsewhere; it replaces the one measured
        from the brightness pattern. A white frame whose every EI is lit (the objective
        pupil larger than the sensor) cannot show the axis: without ``axis`` it is taken at
        the sensor centre, with a warning.

    Returns
    -------
    Calibration

    Raises
    ------
    SsdpcError
        For frames without EI disks and optics that do not match the frame; the message
        names the fix. An unchecked grid is never returned.
    """
    if not isinstance(optics, Optics):
        raise SsdpcError(f"optics must be an Optics (e.g. Optics.from_yaml(path)), got {type(optics).__name__}")
    if kind not in KINDS:
        raise SsdpcError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    img = validated(frame)
    _check_signal(frame, img)
    flip = np.diag([-1.0 if optics.flip_x else 1.0, -1.0 if optics.flip_y else 1.0])
    pitch0 = optics.pitch_px
    r0 = min(optics.ei_radius_px, 0.7 * pitch0)

    # 1. EI disks: candidates -> robust rim circles -> lattice indices -> rim fits
    if guess is None:
        cand = find_disks(img, pitch0, r0)
    else:
        g = np.asarray(guess, float).reshape(-1, 2)
        cand = Candidates(g, np.ones(len(g)), noise_sigma(img), float(np.percentile(img, 2)))
    measured = _measure_disks(img, cand, r0, pitch0)
    circles = [c for c, _ in measured]
    lat, n_idx, on = assign(
        np.array([c.centre for c in circles]).reshape(-1, 2),
        np.array([s for _, s in measured]),
        pitch0,
        flip,
        lattice_cell(optics.grid),
    )
    circles = [c for c, keep in zip(circles, on) if keep]
    circles, n_idx, bright = all_rims(img, lat, circles, n_idx)
    xy, sig, radii, held = refine_centres(img, lat, circles, n_idx, cand.dark)
    # a neighbour's skirt pulls some rims; the soft-disk fit models it on EIs that are not small
    shone = outshone(img, xy, n_idx, float(np.median(radii)))
    reliable = ~shone | (held & (float(np.median(radii)) >= SMALL_EI_PX))
    whole = bool(bright.sum() >= FULL_PUPIL * pupil_lenslets(optics, len(all_cells(lat, img.shape))))
    lat, res, trusted = fit_lattice(xy, n_idx, sig, lat.pitch, flip, reliable, lat.cell, whole_array=whole)
    _check_prior(lat, float(np.median(radii[trusted])), optics)
    r_ei = float(np.median(radii[trusted]))
    rms = float(np.sqrt(np.mean(np.sum(res[trusted] ** 2, axis=1))))
    if rms > MAX_LATTICE_RMS * lat.pitch:
        raise SsdpcError(
            f"elemental-image centres scatter by {100 * rms / lat.pitch:.1f}% of the pitch about one lattice; "
            "check that the frame is an undistorted raw light-field frame of this instrument"
        )
    # per-lenslet centres: every reliable, bright rim that agrees with the lattice
    keep = reliable & bright & (np.hypot(res[:, 0], res[:, 1]) < OUTLIER * lat.pitch)
    # an EI cut by the frame's edge shows part of its rim, which leaves its centre and radius
    # trading off: its lattice position is better (0.5 px better on a 15 px pitch)
    H, W = img.shape
    edge = 1.2 * r_ei + 1  # the rim and its blur
    keep &= np.all((xy > edge) & (xy < np.array([W, H]) - 1 - edge), axis=1)
    if trusted.sum() < MIN_AFFINE and not whole:
        # a few lit EIs of a flat or sample frame: a lit neighbour's skirt pulls the rim of a dim EI
        # by pixels; only rims that nothing outshines keep their own centre (a small array's white
        # frame lights all its EIs and keeps them all)
        keep &= held & ~shone
    meas = {tuple(int(v) for v in n): c for n, c, k in zip(n_idx, xy, keep) if k}

    # 2. optical axis and kind from the brightness pattern of all EIs
    cells = all_cells(lat, img.shape)
    xy_all = np.array([meas.get(tuple(int(v) for v in np.rint(lat.index(c))), c) for c in cells]).reshape(-1, 2)
    b_all = ei_brightness(img, xy_all, r_ei, _INNER["white"])
    auto_kind, full, evidence = decide_kind(img, b_all, xy[trusted], r_ei, optics)
    if kind == "auto":
        kind = auto_kind
    else:
        full = kind == "white"
        evidence = {**evidence, "certainty": "given"}
    if _INNER[kind] != _INNER["white"]:
        b_all = ei_brightness(img, xy_all, r_ei, _INNER[kind])
    if axis is None:
        axis, axis_rms, par = _axis(xy_all, b_all, lat, optics, full, kind, img.shape)
        evidence["axis"] = "sensor centre (assumed)" if par is None else "measured"
    else:
        axis, axis_rms, par = _given_axis(axis, img.shape), float("nan"), None
        evidence["axis"] = "given"
    if par is None:  # no brightness model: brightness relative to the lit EIs' median
        lit = b_all[np.isfinite(b_all)]
        par = np.array([0.0, 0.0, float(np.median(lit[lit > 0.5 * lit.max()])), 0.0])

    # 3. grid, labels and the per-lenslet table from the measured centres
    grid, shift = _make_grid(lat, axis, optics)
    lens, centres, dev, is_meas = _table(grid, shift, lat, meas, optics)
    rel = (ei_brightness(img, centres, r_ei, _INNER[kind]) - par[3]) / par[2]
    _warn_deviations(lens, dev, lat.pitch)
    if r_ei > 0.5 * lat.pitch + 2:
        warnings.warn(
            f"EIs overlap (radius {r_ei:.1f} px > half pitch {0.5 * lat.pitch:.1f} px); close the field iris a little",
            SsdpcWarning,
            stacklevel=2,
        )
    cal = Calibration(
        grid=grid,
        ei_radius_px=r_ei,
        optics=optics,
        frame_shape=(int(img.shape[0]), int(img.shape[1])),
        lenslets=lens,
        centres_px=centres,
        brightness=rel,
        residual_px=rms,
        axis_rms=axis_rms,
        kind=kind,
        n_fitted=len(meas),
        deviation_px=dev,
        measured=is_meas,
        shear_deg=lat.shear_deg,
        aspect=lat.aspect,
        kind_evidence={**evidence, "guided": guess is not None},
    )
    if kind == "white":  # the condenser open: the rims are the field stop's image through each lenslet
        cal.rim_defocus_waves = d = rim_defocus(img, cal, optics)
        if d is not None and rims_unmodelled(d, optics):
            warnings.warn(rims_notice(d), SsdpcWarning, stacklevel=2)
    return cal


def _check_prior(lat: AffineLattice, r_ei: float, optics: Optics) -> None:
    """The measured pitch must agree with the optics within 5 % (else an error naming the
    keys); an EI radius more than 5 % off gives a warning naming ``iris_radius_um``."""
    pitch0 = optics.pitch_px
    if abs(lat.pitch / pitch0 - 1) > PRIOR_TOLERANCE:
        pitch_um = lat.pitch * optics.pixel_um
        raise SsdpcError(
            f"lenslet pitch on the frame is {lat.pitch:.2f} px but the optics give {pitch0:.2f} px "
            f"(mla.pitch_um / sensor.pixel_um); fix mla.pitch_um (the frame says {pitch_um:.4g} µm at "
            f"{optics.pixel_um:g} µm pixels) or sensor.pixel_um (binning?) in the optics file"
        )
    if abs(r_ei / optics.ei_radius_px - 1) > PRIOR_TOLERANCE:
        iris = r_ei * optics.pixel_um * optics.fourier_lens_mm / optics.mla_focal_length_mm
        warnings.warn(
            f"elemental-image radius on the frame is {r_ei:.1f} px but the optics give "
            f"{optics.ei_radius_px:.1f} px; the measured radius is used. If the field stop was changed, set "
            f"iris_radius_um to {iris:.4g} in the optics file (small EIs measure a little small: their rims "
            "are blurred)",
            SsdpcWarning,
            stacklevel=3,
        )


def _axis(xy_all, b_all, lat, optics, full, kind, shape):
    """Optical axis from the brightness pattern: the objective pupil when the whole pupil
    is lit, else the condenser disk. Returns axis (x, y) px, relative rms, fit parameters
    (None when the pupil's edge is off the sensor and the axis is assumed)."""
    um_per_px = optics.pitch_um / lat.pitch
    r_pupil = optics.pupil_radius_mla_um
    if full:
        ok = np.isfinite(b_all)
        lit = int(np.count_nonzero(b_all[ok] > np.percentile(b_all[ok], 5) + 0.25 * np.ptp(b_all[ok])))
        dark = int(np.count_nonzero(b_all[ok] < 0.25 * b_all[ok].max()))
        if dark < MIN_DARK_CELLS:  # every EI lit: the pupil's edge is off the sensor
            centre = _given_axis(None, shape)
            warnings.warn(
                f"all {int(ok.sum())} elemental images on the sensor are lit, so the objective pupil's edge "
                f"(the optical axis) is not on this frame; the axis is taken at the sensor centre "
                f"({centre[0]:.1f}, {centre[1]:.1f}) px. If it is elsewhere, give it: ssdpc calibrate --axis X Y",
                SsdpcWarning,
                stacklevel=3,
            )
            return centre, float("nan"), None
        axis, axis_rms, axis_sig, par = fit_axis(xy_all, b_all, r_pupil, um_per_px, optics, tilt=lit >= FEW_LENSLETS)
        what = f"the objective pupil (NA {optics.na})"
    else:
        r_src = optics.sigma * r_pupil
        if r_src <= 0:
            raise SsdpcError(
                "condenser_na is 0, so a flat/sample frame cannot locate the optical axis; "
                "calibrate on a white frame taken with the condenser fully open"
            )
        axis, axis_rms, axis_sig, par = fit_axis(xy_all, b_all, r_src, um_per_px, optics, tilt=False)
        what = f"the condenser disk (condenser_na {optics.condenser_na})"
    if axis_rms > MAX_AXIS_RMS or not axis_sig < 0.005 * lat.pitch:
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
            stacklevel=3,
        )
    return axis, axis_rms, par


def _given_axis(axis, shape) -> np.ndarray:
    """``axis`` (x, y) px checked to lie on the frame; None: the sensor centre."""
    H, W = shape
    if axis is None:
        return np.array([(W - 1) / 2, (H - 1) / 2])
    a = np.asarray(axis, float).ravel()
    if a.shape != (2,) or not np.all(np.isfinite(a)) or not (0 <= a[0] <= W - 1 and 0 <= a[1] <= H - 1):
        raise SsdpcError(f"axis {axis} must be (x, y) in px on the {W} x {H} frame; give --axis X Y inside it")
    return a


def _make_grid(lat: AffineLattice, axis, optics) -> tuple[Grid, np.ndarray]:
    """Grid whose reference vertex is the lattice vertex nearest the optical axis, and the
    lattice index of lenslet (row 0, col 0)."""
    shift = np.rint(lat.index(axis) + 0.5)  # axis in vertex units (vertex of cell n at n − ½)
    vertex = lat.centres(shift - 0.5)
    flips = (optics.flip_x, optics.flip_y)
    grid = Grid(xy_pair(axis), xy_pair(vertex), float(lat.pitch), float(lat.theta_deg), *flips, optics.grid)
    return grid, shift


def _table(grid: Grid, shift, lat: AffineLattice, meas: dict, optics: Optics):
    """Lenslets with a_k, u_k and fraction from their measured centres; the centres,
    deviations from the lattice (NaN where not measured) and the measured mask."""
    um_per_px = optics.pitch_um / lat.pitch
    A_inv = np.linalg.inv(grid.matrix)
    axis = np.asarray(grid.axis_px)
    lens, centres, dev = [], [], []
    for ln in grid.lenslets(optics):
        n = (int(shift[0]) + ln.col, int(shift[1]) + ln.row)
        ideal = lat.centres(n)
        c = meas.get(n)
        centres.append(ideal if c is None else c)
        dev.append(np.full(2, np.nan) if c is None else c - ideal)
        a = A_inv @ (centres[-1] - axis) * um_per_px
        u = mla_to_frequency(optics, a)
        frac = float(circle_overlap_fraction(math.hypot(*a), optics.lenslet_radius_um, optics.pupil_radius_mla_um))
        lens.append(Lenslet(ln.row, ln.col, (float(a[0]), float(a[1])), (float(u[0]), float(u[1])), frac))
    dev_a = np.array(dev).reshape(-1, 2)
    return lens, np.array(centres).reshape(-1, 2), dev_a, np.isfinite(dev_a).all(axis=1)


def _warn_deviations(lens, dev, pitch) -> None:
    d = np.hypot(*dev.T)
    far = np.isfinite(d) & (d > DEVIATION_WARN * pitch)
    if far.any():
        k = int(np.nanargmax(d))
        warnings.warn(
            f"{int(far.sum())} lenslet(s) sit more than {100 * DEVIATION_WARN:.0f}% of the pitch off a perfect "
            f"lattice (largest {d[k]:.2f} px = {100 * d[k] / pitch:.1f}% at row {lens[k].row}, col "
            f"{lens[k].col}); each EI is extracted at its own measured centre",
            SsdpcWarning,
            stacklevel=3,
        )
