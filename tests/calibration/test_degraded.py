"""Calibration on the frames real instruments make, from the simulator with known truth.

Imperfect arrays (per-lenslet offsets up to 3 % of the pitch, a 1° shear between the
lattice axes), 8-bit cameras, bright sample content in every EI, a lens-mount shadow
notching every EI rim, strong vignetting, and pitches from 15 px to 400 px.

Targets: every EI centre within 0.2 % of the pitch (at least 0.5 px), for the lenslets
with at least 35 % of their aperture inside the pupil (EIs whose rim is less than a
quarter as steep as the median, about 30 % lit, take their lattice position: see
docs/calibration.md); the EI radius within 1 %.
"""

import math
import warnings

import numpy as np
import pytest

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation import imperfect
from napari_ssdpc.simulation.camera import Camera
from napari_ssdpc.simulation.imaging import array_as_built
from napari_ssdpc.simulation.sample_free import white_frame, white_intensity

PAPER = Optics.paper()
GRID = Grid.nominal(PAPER, axis_offset_px=(21.3, -33.7), rotation_deg=4.0)
MIN_FRACTION = 0.35
RADIUS_REL = 0.01


def optics_with_pitch(pitch_px: float) -> Optics:
    """The paper's optics on a camera whose pixels give ``pitch_px``, just big enough for the pupil."""
    o = PAPER.replace(pixel_um=PAPER.pitch_um / pitch_px)
    side = int(2 * o.pupil_radius_mla_um / o.pixel_um + 3 * pitch_px)
    return o.replace(width_px=side, height_px=side)


def calibrate_degraded(optics, grid, *, array=None, degrade=None, camera=None, seed=0):
    """Calibrate a degraded white frame; return (worst EI-centre error px, tolerance px,
    relative radius error, the calibration)."""
    grid, cam, truth, centres = array_as_built(optics, grid, camera, array)
    intensity = white_intensity(optics, grid, cam, array=array)
    if degrade is not None:
        intensity = degrade(intensity, centres, optics.ei_radius_px)
    frame = cam.apply(intensity, cam.rng(seed))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = calibrate(frame, optics)
    frac = np.array([ln.fraction for ln in truth])
    d = np.hypot(*(cal.centres_px[:, None, :] - centres[None, :, :]).transpose(2, 0, 1))
    worst = float(d.min(axis=0)[frac >= MIN_FRACTION].max())
    tol = max(0.002 * grid.pitch_px, 0.5)
    return worst, tol, cal.ei_radius_px / optics.ei_radius_px - 1, cal


def check(name, **kw):
    worst, tol, r_err, cal = calibrate_degraded(kw.pop("optics", PAPER), kw.pop("grid", GRID), **kw)
    print(f"{name}: worst EI centre {worst:.3f} px (target {tol:.2f}), radius {100 * r_err:+.2f} %")
    assert worst < tol, f"{name}: EI centre off by {worst:.3f} px (target {tol:.2f} px)"
    assert abs(r_err) < RADIUS_REL, f"{name}: radius off by {100 * r_err:.2f} %"
    return cal


def test_imperfect_array_offsets_and_shear():
    """Offsets up to 3 % of the pitch and a 1° shear: each EI is found where it is, the
    shear is measured, and the deviations are reported with a warning."""
    arr = imperfect.ArrayErrors(offset_frac=0.03, shear_deg=1.0, seed=1)
    cal = check("offsets 3 % + shear 1°", array=arr)
    assert cal.shear_deg == pytest.approx(1.0, abs=0.1)
    assert 0.01 * cal.grid.pitch_px < cal.max_deviation_px < 0.06 * cal.grid.pitch_px
    row = cal.table[0]
    assert {"measured", "deviation_px"} <= set(row)
    frame = white_frame(PAPER, GRID, array=arr, rng=2)
    with pytest.warns(UserWarning, match="off a perfect lattice"):
        calibrate(frame, PAPER)


def _misfit_over_rho(u, u_true, rho):
    """Each sub-aperture centre's distance from the truth over the sub-aperture radius, after the
    rotation and shift that best match the two sets (the frame of the views is a choice)."""
    from scipy.linalg import orthogonal_procrustes

    a, b = u_true - u_true.mean(axis=0), u - u.mean(axis=0)
    return np.hypot(*(a @ orthogonal_procrustes(a, b)[0] - b).T) / rho


def test_sub_apertures_are_where_the_lenslets_are():
    """Lenslets moved by up to 3 % of the pitch (4.3 px) and sheared by 1°: each sub-aperture's
    centre in the pupil comes from its own EI's centre, within 1 % of its radius (measured 0.8 %;
    the lattice's sites are off by up to 10 %)."""
    arr = imperfect.ArrayErrors(offset_frac=0.03, shear_deg=1.0, seed=1)
    _, _, truth, centres = array_as_built(PAPER, GRID, None, arr)
    cal = calibrate_degraded(PAPER, GRID, array=arr)[3]
    near = np.hypot(*(cal.centres_px[:, None, :] - centres[None, :, :]).transpose(2, 0, 1)).argmin(axis=1)
    lit = np.array([truth[k].fraction for k in near]) >= MIN_FRACTION
    u_true = np.array([truth[k].u for k in near])[lit]
    u_cal = np.array([ln.u for ln in cal.lenslets])[lit]
    sites = {(ln.row, ln.col): ln.u for ln in GRID.lenslets(PAPER)}
    u_lattice = np.array([sites[ln.row, ln.col] for ln in cal.lenslets])[lit]
    rho = PAPER.subaperture_radius
    assert _misfit_over_rho(u_cal, u_true, rho).max() < 0.01
    assert _misfit_over_rho(u_lattice, u_true, rho).max() > 0.05  # the check can see a misplaced lenslet


def test_perfect_array_reports_no_deviation():
    cal = check("perfect array")
    assert cal.max_deviation_px < 0.1 and abs(cal.shear_deg) < 0.01


def test_eight_bit_camera():
    check("8-bit", camera=Camera(bit_depth=8, gain_adu_per_e=0.015, dark_offset_adu=10))


def test_float_frame_of_any_scale():
    cam = Camera()
    frame = cam.apply(white_intensity(PAPER, GRID, cam), cam.rng(3)).astype(np.float32) / 4095.0
    cal = calibrate(frame, PAPER)
    assert math.hypot(*np.subtract(cal.grid.axis_px, GRID.axis_px)) < 0.1


def test_bright_sample_content_in_every_ei():
    cal = check(
        "bright content",
        camera=Camera(exposure_e=6000),
        degrade=lambda i, c, r: imperfect.content(i, c, r, contrast=1.0, seed=2),
    )
    assert cal.kind == "sample" and cal.kind_evidence["content_score"] > 5


def test_notched_eis():
    check("notched", degrade=lambda i, c, r: imperfect.notch(i, c, r))


def test_strong_vignetting():
    check("vignetting", degrade=lambda i, c, r: imperfect.vignetting(i, 0.5))


@pytest.mark.slow
@pytest.mark.parametrize("pitch_px", [15, 20, 30, 60, 145, 400])
def test_pitch_range(pitch_px):
    o = optics_with_pitch(pitch_px)
    g = Grid.nominal(o, axis_offset_px=(0.13 * pitch_px, -0.21 * pitch_px), rotation_deg=2.0)
    check(f"pitch {pitch_px} px", optics=o, grid=g, array=imperfect.ArrayErrors(0.02, 0.5, seed=5))


# ------------------------------------------------------------------ hexagonal arrays
HEX = PAPER.replace(grid="hex")


@pytest.mark.parametrize("rotation_deg, flip_x", [(3.0, False), (-20.0, True)])
def test_hexagonal_array(rotation_deg, flip_x):
    """A hex array (rows offset by half a pitch, six neighbours): lattice, labels, axis and
    each lenslet's u_k agree with the simulator's truth, rotated up to ±30° and mirrored."""
    optics = HEX.replace(flip_x=flip_x)
    grid = Grid.nominal(optics, axis_offset_px=(5.3, -31.0), rotation_deg=rotation_deg)
    worst, tol, r_err, cal = calibrate_degraded(optics, grid)
    print(f"hex {rotation_deg:+g}°: worst EI centre {worst:.3f} px (target {tol:.2f}), radius {100 * r_err:+.2f} %")
    assert worst < tol and abs(r_err) < RADIUS_REL
    assert cal.grid.lattice == "hex" and abs(cal.shear_deg) < 0.05 and abs(cal.aspect) < 1e-3
    assert math.hypot(*np.subtract(cal.grid.axis_px, grid.axis_px)) < 0.25
    assert cal.grid.rotation_deg == pytest.approx(rotation_deg, abs=0.02)
    truth = {(ln.row, ln.col): ln for ln in grid.lenslets(optics)}
    assert {(ln.row, ln.col) for ln in cal.lenslets} == set(truth)  # the same labels
    du = max(math.hypot(*np.subtract(ln.u, truth[ln.row, ln.col].u)) for ln in cal.lenslets)
    assert du < 1e-3 * optics.pitch_um / (optics.wavelength_um * optics.f_obj_um * optics.m_r)  # 0.1 % of a step


# ------------------------------------------------- an array larger than the pupil's image on the sensor
def small_lenslet_optics(width_px, height_px):
    """Lenslets of 83 µm and f 2.55 mm (F/30) on 5.6 µm pixels: a 15 px pitch, the objective
    pupil 36 lenslets across, so the sensor sees a 28 x 28 patch of lit EIs (or fewer)."""
    d = PAPER.to_dict()
    d["mla"] = {"pitch_um": 500 / 6, "focal_length_mm": 15.3 / 6, "lenslet_radius_um": 250 / 6, "grid": "square"}
    d["sensor"] = {**d["sensor"], "pixel_um": 500 / 6 / 15, "width_px": width_px, "height_px": height_px}
    return Optics.from_dict(d, source="optics")


def test_pupil_filling_the_sensor():
    """A 28 x 28 patch of touching 15 px EIs with strongly blurred rims (w ≈ R/5): only the
    sensor's corners lie beyond the pupil. The lattice, every EI, the radius and the axis
    (from the dark corners) are measured."""
    optics = small_lenslet_optics(430, 420)
    grid = Grid.nominal(optics, axis_offset_px=(3.3, -2.1), rotation_deg=1.0)
    worst, tol, r_err, cal = calibrate_degraded(optics, grid, array=imperfect.ArrayErrors(0.02, 0.5, seed=3))
    axis = math.hypot(*np.subtract(cal.grid.axis_px, grid.axis_px))
    print(f"28 x 28: worst EI centre {worst:.3f} px, radius {100 * r_err:+.2f} %, axis {axis:.3f} px")
    assert worst < tol and abs(r_err) < RADIUS_REL
    assert cal.kind == "white" and cal.kind_evidence["axis"] == "measured" and axis < 0.25
    assert abs(cal.grid.pitch_px / 15 - 1) < 1e-4


def test_every_ei_lit_axis_assumed_or_given():
    """A 20 x 20 patch inside the pupil: nothing shows the axis. The grid still calibrates;
    the axis is the sensor centre with a warning naming --axis, or the one given."""
    optics = small_lenslet_optics(300, 300)
    grid = Grid.nominal(optics, axis_offset_px=(-4.2, 1.7), rotation_deg=-0.6)
    cam = Camera()
    frame = cam.apply(white_intensity(optics, grid, cam), cam.rng(1))
    with pytest.warns(UserWarning, match="--axis"):
        cal = calibrate(frame, optics)
    assert cal.kind == "white" and cal.kind_evidence["axis"] == "sensor centre (assumed)"
    assert np.allclose(cal.grid.axis_px, (149.5, 149.5)) and not np.isfinite(cal.axis_rms)
    assert abs(cal.grid.pitch_px / 15 - 1) < 1e-4 and abs(cal.grid.rotation_deg + 0.6) < 0.01
    cal = calibrate(frame, optics, axis=grid.axis_px)
    assert np.allclose(cal.grid.axis_px, grid.axis_px) and cal.kind_evidence["axis"] == "given"
    truth = grid.lattice_px([ln.row for ln in cal.lenslets], [ln.col for ln in cal.lenslets])
    on = cal.measured
    assert np.abs(truth[on] - cal.centres_px[on]).max() < 0.5 and on.sum() > 300
    with pytest.raises(SsdpcError, match="--axis"):
        calibrate(frame, optics, axis=(400.0, 10.0))


# ------------------------------------------------------------------ a 3 x 3 array
def three_by_three(pitch_px):
    """Nine lenslets across the objective pupil (the corners half inside it), EIs ``pitch_px`` apart."""
    pitch = 2 * PAPER.pupil_radius_mla_um / 3
    d = PAPER.to_dict()
    d["mla"] = {"pitch_um": pitch, "focal_length_mm": 15.3 * pitch / PAPER.pitch_um, "lenslet_radius_um": pitch / 2}
    side = int(3.6 * pitch_px)
    d["sensor"] = {**d["sensor"], "pixel_um": pitch / pitch_px, "width_px": side, "height_px": side}
    return Optics.from_dict(d, source="optics")


@pytest.mark.parametrize(
    "name, degrade",
    [
        ("white", None),
        ("content + notch", lambda i, c, r: imperfect.notch(imperfect.content(i, c, r, contrast=1.0, seed=2), c, r)),
    ],
)
def test_three_by_three_array(name, degrade):
    """A 3 x 3 array with the central lenslet on the axis, offsets of 1.2 % of the pitch and a
    1° shear (EIs 1-6 px off a square lattice): every EI keeps its own centre, the shear is
    measured, on a white frame and on one with sample content and a notch in every EI."""
    optics = three_by_three(300)
    p = optics.pitch_px
    grid = Grid.nominal(optics, axis_offset_px=(0.5 * p + 3.1, 0.5 * p - 4.2), rotation_deg=2.5)
    arr = imperfect.ArrayErrors(0.012, 1.0, seed=4)
    cam = Camera(exposure_e=6000)
    worst, tol, r_err, cal = calibrate_degraded(optics, grid, array=arr, degrade=degrade, camera=cam)
    print(f"3 x 3, {name}: worst EI centre {worst:.3f} px (target {tol:.2f}), radius {100 * r_err:+.2f} %")
    assert worst < tol and abs(r_err) < RADIUS_REL
    assert cal.measured.sum() == 9 and cal.shear_deg == pytest.approx(1.0, abs=0.1)
