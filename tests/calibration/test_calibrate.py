"""Lenslet-grid calibration and EI extraction, checked against the simulator's ground-truth Grid.

Targets on white frames (condenser fully open): optical axis and EI centres within 0.25 px,
pitch within 0.1 %, rotation within 0.05°, for axis offsets up to ±half a pitch and
rotations up to ±5°. Flat and sample frames (σ < 1, few lit lenslets) keep the lattice
targets; their optical axis comes from the lit-lenslet pattern and is held to 1 px
(documented in docs/calibration.md).
"""

import json
import math
import pathlib
import warnings

import numpy as np
import pytest

from napari_ssdpc.calibration import Calibration, calibrate, extract_views, insert_views, overlay_png
from napari_ssdpc.calibration.result import CALIBRATION_VERSION
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.multislice import Source
from napari_ssdpc.simulation.phantom_base import Composite
from napari_ssdpc.simulation.phantoms import pmma_bead
from napari_ssdpc.simulation.primitives import Box
from napari_ssdpc.simulation.sample_free import flat_frame, flat_intensity, white_frame, white_intensity
from napari_ssdpc.simulation.simulate import simulate

OPTICS = Optics.paper()
P = OPTICS.pitch_px
AXIS_PX, EI_PX, PITCH_REL, ROT_DEG = 0.25, 0.25, 1e-3, 0.05
FLAT_AXIS_PX = 1.0


def random_grids(n, seed):
    """Grids with random axis offsets (±half a pitch) and rotations (±5°), seeded."""
    rng = np.random.default_rng(seed)
    return [
        Grid.nominal(
            OPTICS, axis_offset_px=tuple(rng.uniform(-0.5, 0.5, 2) * P), rotation_deg=float(rng.uniform(-5, 5))
        )
        for _ in range(n)
    ]


SWEEP = random_grids(12, seed=2024)
EXTREMES = [
    Grid.nominal(OPTICS, axis_offset_px=(0.49 * P, -0.49 * P), rotation_deg=5.0),
    Grid.nominal(OPTICS, axis_offset_px=(-0.45 * P, 0.2 * P), rotation_deg=-5.0),
]


def grid_errors(cal, truth):
    """(axis error px, worst EI-centre error px, relative pitch error, rotation error °).

    EI centres are matched by position, since the (row, col) labels depend on which
    vertex is nearest the axis (a tie at exactly half a pitch): every true lenslet with
    at least 1 % inside the pupil must have a detected centre nearby and every detected
    one with at least 2 % a true one (the gap keeps a lenslet whose fraction sits right
    at the threshold from counting as missing)."""
    true_lens = truth.lenslets(OPTICS)
    tc = truth.lattice_px([ln.row for ln in true_lens], [ln.col for ln in true_lens])
    t_frac = np.array([ln.fraction for ln in true_lens])
    o_frac = np.array([ln.fraction for ln in cal.lenslets])
    d = np.hypot(*(cal.centres_px[:, None, :] - tc[None, :, :]).transpose(2, 0, 1))
    ei = max(d.min(axis=0)[t_frac >= 0.01].max(), d.min(axis=1)[o_frac >= 0.02].max())
    axis = math.hypot(*np.subtract(cal.grid.axis_px, truth.axis_px))
    return axis, float(ei), abs(cal.grid.pitch_px / truth.pitch_px - 1), abs(cal.grid.rotation_deg - truth.rotation_deg)


def check_white(grid, seed):
    frame = white_frame(OPTICS, grid=grid, rng=seed)
    cal = calibrate(frame, OPTICS)
    axis, ei, pitch, rot = grid_errors(cal, grid)
    assert cal.kind == "white"
    assert axis < AXIS_PX, f"axis error {axis:.3f} px"
    assert ei < EI_PX, f"EI centre error {ei:.3f} px"
    assert pitch < PITCH_REL, f"pitch error {100 * pitch:.4f} %"
    assert rot < ROT_DEG, f"rotation error {rot:.4f} deg"
    # the per-lenslet table agrees with the ground truth where the labels agree
    if np.all(np.abs(grid.axis_offset_px()) < 0.45 * P):
        truth = {(ln.row, ln.col): ln for ln in grid.lenslets(OPTICS)}
        for ln in cal.lenslets:
            assert ln.fraction == pytest.approx(truth[(ln.row, ln.col)].fraction, abs=2e-3)
            assert ln.halves == truth[(ln.row, ln.col)].halves or min(map(abs, ln.a_um)) < 2.0
    return cal, frame


# ------------------------------------------------------------------ white frames
@pytest.fixture(scope="module")
def white():
    """A calibrated white frame of a rotated grid with an axis offset."""
    grid = SWEEP[0]
    cal, frame = check_white(grid, seed=0)
    return grid, frame, cal


def test_white_frame_accuracy(white):
    grid, frame, cal = white
    assert cal.residual_px < 0.05 and cal.axis_rms < 0.01
    # the brightness column follows the lit fraction inside the pupil
    b = np.array([ln.fraction for ln in cal.lenslets])
    assert np.nanmax(np.abs(cal.brightness - b)) < 0.03
    assert cal.ei_radius_px == pytest.approx(OPTICS.ei_radius_px, abs=1.0)


@pytest.mark.parametrize("case", [1, 2])
def test_white_frame_random_cases(case):
    check_white(SWEEP[case], seed=case)


@pytest.mark.parametrize("case", [0, 1])
def test_white_frame_extreme_offset_and_rotation(case):
    check_white(EXTREMES[case], seed=10 + case)


@pytest.mark.slow
def test_white_frame_sweep():
    """All 12 seeded random offsets/rotations and the 2 extremes; prints the worst errors."""
    cases = [(g, k) for k, g in enumerate(SWEEP)] + [(g, 10 + k) for k, g in enumerate(EXTREMES)]
    worst = np.zeros(4)
    for grid, seed in cases:
        cal, _ = check_white(grid, seed=seed)
        worst = np.maximum(worst, grid_errors(cal, grid))
    print(
        f"worst of {len(cases)} white frames: axis {worst[0]:.3f} px, EI {worst[1]:.3f} px, "
        f"pitch {100 * worst[2]:.4f} %, rotation {worst[3]:.4f} deg"
    )


def test_flipped_camera_keeps_labels():
    optics = OPTICS.replace(flip_x=True)
    grid = Grid.nominal(optics, axis_offset_px=(25.0, -40.0), rotation_deg=-3.3)
    cal = calibrate(white_frame(optics, grid=grid, rng=4), optics)
    tc = grid.lattice_px([ln.row for ln in cal.lenslets], [ln.col for ln in cal.lenslets])
    assert np.abs(tc - cal.centres_px).max() < EI_PX
    assert np.allclose(cal.grid.matrix, grid.matrix, atol=1e-3)


# --------------------------------------------------------- flat and sample frames
def check_flat(grid, seed):
    frame = flat_frame(OPTICS, grid=grid, rng=seed)
    with pytest.warns(SsdpcWarning, match="white frame"):
        cal = calibrate(frame, OPTICS)
    axis, ei, pitch, rot = grid_errors(cal, grid)
    assert cal.kind == "flat"
    assert ei < EI_PX and pitch < PITCH_REL and rot < ROT_DEG, (ei, pitch, rot)
    assert axis < FLAT_AXIS_PX, f"axis error {axis:.3f} px"
    return np.array([axis, ei, pitch, rot])


@pytest.mark.xfail(
    strict=True,
    reason="measured: EI centres 0.81 px off (target 0.25 px): the rim a lit neighbour pulls 2.3 px is left out, "
    "but a second one 0.4 px off still turns the 4-EI lattice by 0.08°",
)
def test_flat_frame_few_lit_lenslets():
    """σ = 0.25: only the lenslets near the axis are lit; the lattice is still exact and
    the axis comes from their brightness pattern (with a warning)."""
    check_flat(SWEEP[3], seed=3)


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="measured: 8 of 10 flat frames calibrate, worst EI centre 0.257 px (target 0.25 px); "
    "2 light only 2 EIs and are refused with a one-line error",
)
def test_flat_frame_sweep():
    worst = np.max([check_flat(g, seed=20 + k) for k, g in enumerate(SWEEP[:10])], axis=0)
    print(
        f"worst of 10 flat frames: axis {worst[0]:.3f} px, EI {worst[1]:.3f} px, "
        f"pitch {100 * worst[2]:.4f} %, rotation {worst[3]:.4f} deg"
    )


def check_sample(grid, source, check_axis):
    res = simulate(pmma_bead(), OPTICS, grid=grid, source=source, rng=5)
    with pytest.warns(SsdpcWarning, match="white frame"):
        cal = calibrate(res.frame, OPTICS)
    axis, ei, pitch, rot = grid_errors(cal, grid)
    assert cal.kind == "sample"
    assert ei < EI_PX and pitch < PITCH_REL and rot < ROT_DEG, (ei, pitch, rot)
    if check_axis:
        assert axis < FLAT_AXIS_PX, f"axis error {axis:.3f} px"
    return np.array([axis, ei, pitch, rot])


@pytest.mark.xfail(strict=True, reason="measured: EI centres 0.72 px off (target 0.25 px) with 4 lit EIs")
def test_sample_frame_lattice():
    """The paper's PMMA bead (σ = 0.25). A coarse condenser sampling (Source step 4)
    keeps this fast; it quantises the lit-lenslet brightness by a few per cent, which
    moves the axis by up to ~1 px, so only the lattice is checked here and the axis in
    the slow test below at the simulator's default source sampling."""
    check_sample(SWEEP[4], Source(step=4), check_axis=False)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="measured: 1.5 px on the first of 2 sample frames (4 lit EIs), target 0.25 px")
def test_sample_frame_axis():
    worst = np.max([check_sample(SWEEP[k], None, check_axis=True) for k in (4, 5)], axis=0)
    print(
        f"worst of 2 sample frames: axis {worst[0]:.3f} px, EI {worst[1]:.3f} px, "
        f"pitch {100 * worst[2]:.4f} %, rotation {worst[3]:.4f} deg"
    )


# ---------------------------------------------------------------- bad input
def _one_line_error(fn, *words):
    with pytest.raises(SsdpcError) as e:
        fn()
    msg = str(e.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


def test_bad_frames(white):
    _, frame, _ = white
    shape = frame.shape
    rng = np.random.default_rng(1)
    nan = frame.astype(float)
    nan[100, 100] = np.nan
    cases = [
        (np.full(shape, 100, np.uint16), "blank"),
        (rng.normal(100, 5, shape).astype(np.uint16), "no elemental images"),
        (rng.poisson(2000, shape).astype(np.uint16), "no elemental images"),
        (np.minimum(frame.astype(np.int32) * 3, 4095).astype(np.uint16), "saturated"),
        (frame.astype(np.complex64), "dtype"),
        (np.stack([frame, frame]), "2D"),
        (frame[0], "2D"),
        (nan, "NaN"),
    ]
    for bad, words in cases:
        _one_line_error(lambda: calibrate(bad, OPTICS), words)  # noqa: B023
    _one_line_error(lambda: calibrate(frame, OPTICS, kind="grey"), "kind")
    _one_line_error(lambda: calibrate(frame, "paper"), "Optics")


def test_optics_that_do_not_match_the_frame(white):
    _, frame, _ = white
    _one_line_error(lambda: calibrate(frame, OPTICS.replace(pixel_um=3.8)), "pitch", "sensor.pixel_um")
    _one_line_error(lambda: calibrate(frame, OPTICS.replace(pitch_um=250, lenslet_radius_um=125)), "pitch")
    _one_line_error(lambda: calibrate(frame, OPTICS.replace(na=0.3, condenser_na=0.05)), "objective NA")
    # a white frame called a flat frame: its brightness does not follow the condenser disk
    _one_line_error(lambda: calibrate(frame, OPTICS, kind="flat"), "condenser")


def test_too_few_lit_lenslets_asks_for_a_white_frame(white):
    grid, frame, cal = white
    one = np.full_like(frame, 100)
    c = np.round(cal.centres_px[np.argmax(cal.brightness)]).astype(int)
    r = int(cal.ei_radius_px) + 12
    one[c[1] - r : c[1] + r, c[0] - r : c[0] + r] = frame[c[1] - r : c[1] + r, c[0] - r : c[0] + r]
    _one_line_error(lambda: calibrate(one, OPTICS), "white frame")


# ------------------------------------------------------------------------ JSON
def test_json_round_trip(white, tmp_path):
    _, _, cal = white
    path = cal.to_json(tmp_path / "calib.json")
    back = Calibration.from_json(path)
    assert back.grid == cal.grid and back.frame_shape == cal.frame_shape and back.kind == cal.kind
    assert back.optics == cal.optics and back.version == CALIBRATION_VERSION
    assert back.lenslets == cal.lenslets
    assert np.array_equal(back.centres_px, cal.centres_px)
    assert np.allclose(back.brightness, cal.brightness, equal_nan=True)
    d = json.loads(path.read_text())
    assert d["version"] == CALIBRATION_VERSION and len(d["lenslets"]) == len(cal.lenslets)
    row = d["lenslets"][0]
    assert {"row", "col", "centre_px", "u", "fraction", "halves"} <= set(row)


def test_json_bad_files(white, tmp_path):
    _, _, cal = white
    good = cal.to_dict()
    for name, content, words in [
        ("v0.json", json.dumps({**good, "version": 0}), "version"),
        ("nov.json", json.dumps({k: v for k, v in good.items() if k != "version"}), "version"),
        ("trunc.json", json.dumps(good)[:500], "corrupt"),
        ("other.json", json.dumps({"hello": 1}), "not a napari-ssdpc calibration"),
        ("nolens.json", json.dumps({k: v for k, v in good.items() if k != "lenslets"}), "corrupt"),
    ]:
        p = tmp_path / name
        p.write_text(content)
        _one_line_error(lambda: Calibration.from_json(p), words)  # noqa: B023
    _one_line_error(lambda: Calibration.from_json(tmp_path / "missing.json"), "not found")


@pytest.mark.parametrize(
    "edit",
    [
        lambda d: d["lenslets"][0].update(centre_px=[v + 3 for v in d["lenslets"][0]["centre_px"]]),
        lambda d: [r.update(u=[-v for v in r["u"]]) for r in d["lenslets"]],  # would flip the sign of Δn
        lambda d: [p.update(flip_x=not p["flip_x"]) for p in (d["grid"], d["optics"])],  # the lattice with its optics
        lambda d: d.update(ei_radius_px=2 * d["ei_radius_px"]),
        lambda d: d["optics"]["objective"].update(magnification=40.0),
    ],
    ids=["centre+3px", "u-negated", "flip_x", "ei-radius-x2", "magnification-40x"],
)
def test_an_edited_calibration_is_refused_until_resigned(white, tmp_path, capsys, edit):
    """Hand edits of a calibration file (each gave wrong numbers with exit 0) break its checksum:
    a one-line error names both ways out; `ssdpc resign-calibration` accepts a deliberate edit."""
    from napari_ssdpc.cli.main import main

    _, _, cal = white
    path = cal.to_json(tmp_path / "calib.json")
    d = json.loads(path.read_text())
    edit(d)
    path.write_text(json.dumps(d, indent=1))
    _one_line_error(lambda: Calibration.from_json(path), "edited after `ssdpc calibrate` wrote it")
    assert main(["resign-calibration", str(path)]) == 0
    assert "signed anew" in capsys.readouterr().out
    assert Calibration.from_json(path).to_dict() == Calibration.from_dict(d, verify=False).to_dict()


def test_json_write_failure_keeps_the_old_file(white, tmp_path, monkeypatch):
    _, _, cal = white
    path = cal.to_json(tmp_path / "calib.json")
    before = path.read_bytes()

    def half_write(self, text, *a, **k):
        with open(self, "w") as f:
            f.write(text[: len(text) // 2])
        raise OSError("disk full")

    monkeypatch.setattr(pathlib.Path, "write_text", half_write)
    with pytest.raises(SsdpcError, match="disk full; check the path and the disk"):
        cal.to_json(path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calib.json"]


# --------------------------------------------------------------------- overlay
def test_overlay_png(white, tmp_path):
    _, frame, cal = white
    path = overlay_png(frame, cal, tmp_path / "calib.png")
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calib.png"]


# ------------------------------------------------------------------- EI views
def test_extract_views_rotated_grid_point_lands_at_its_pixel():
    """An in-focus absorbing 3 µm square at (40, −30) µm, on a grid rotated by 4°, appears
    in every lit view at pixel (40, −30) / object_pixel_um from the view centre."""
    grid = Grid.nominal(OPTICS, axis_offset_px=(21.3, -33.7), rotation_deg=4.0)
    cal = calibrate(white_frame(OPTICS, grid=grid, rng=7), OPTICS)
    src = Source(step=4)
    xy = np.array([40.0, -30.0])
    obj = Composite((Box((xy[0], xy[1], 0.0), (3.0, 3.0, 0.5), 0.03j),))
    img = simulate(obj, OPTICS, grid=grid, source=src).intensity
    flat = flat_intensity(OPTICS, grid=grid, source=src)
    views, fviews = extract_views(img, cal), extract_views(flat, cal)
    h, w = views.data.shape[1:]
    assert views.data.dtype == np.float32 and len(views.lenslets) == len(cal.lenslets)
    assert views.x_um[(w - 1) // 2] == 0 and np.allclose(np.diff(views.x_um), OPTICS.object_pixel_um)
    assert views.mask[(h - 1) // 2, (w - 1) // 2] and not views.mask[0, 0]
    J, I = np.meshgrid(views.x_um, views.y_um)
    near = np.hypot(J - xy[0], I - xy[1]) < 7.0
    lit = [k for k in range(len(views.lenslets)) if fviews.data[k][(h - 1) // 2, (w - 1) // 2] > 0.3]
    assert len(lit) >= 3
    for k in lit:
        dip = np.where(near, np.clip(1 - views.data[k] / np.maximum(fviews.data[k], 1e-6), 0, None), 0.0)
        centre = np.array([(dip * J).sum(), (dip * I).sum()]) / dip.sum()
        err = np.hypot(*(centre - xy)) / OPTICS.object_pixel_um
        assert dip.max() > 0.05 and err < 0.25, (views.lenslets[k], err)


def test_insert_views_inverts_extract_views(white):
    grid, _, cal = white
    frame = white_intensity(OPTICS, grid=grid)
    back = insert_views(extract_views(frame, cal, order=3), cal, order=3)
    yy, xx = np.mgrid[: frame.shape[0], : frame.shape[1]]
    inner = np.zeros(frame.shape, bool)
    for cx, cy in cal.centres_px:
        inner |= (xx - cx) ** 2 + (yy - cy) ** 2 < (0.85 * cal.ei_radius_px) ** 2
    assert np.abs(back - frame)[inner].max() < 2e-3 * frame[inner].max()


def test_extract_views_shape_mismatch(white):
    _, frame, cal = white
    _one_line_error(lambda: extract_views(frame[:-2], cal), "calibrat")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        v = extract_views(frame, cal, size=(31, 41))
    assert v.data.shape == (len(cal.lenslets), 31, 41)
