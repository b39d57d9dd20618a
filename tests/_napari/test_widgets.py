"""The napari widgets end to end on the sample data (headless: Xvfb via pytest-xvfb).

The bead frames are simulated once and cached (``_sample_data``); the operators use a reduced
z range (-20..20 µm, dz 2 µm) and 3 RL iterations so that the whole module takes seconds.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from napari_ssdpc.physics.design import design
from napari_ssdpc.settings.base import field_range
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import ReconstructionSettings

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify
from napari_ssdpc._napari import sample_data as _sample_data
from napari_ssdpc._napari import widgets as _widgets
from napari_ssdpc.calibration import calibrate
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import MemorySink
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.validation.cases import run_config

Z, DZ, ITER = (-20.0, 20.0), 2.0, 3


@pytest.fixture(scope="module")
def bead():
    return _sample_data.bead_frames()  # frame, flat, white, optics (cached on disk)


@pytest.fixture
def errors(monkeypatch):
    """Messages shown with napari's show_error by the widgets."""
    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    return shown


def _docks(viewer):
    out = {}
    for name, cls in (
        ("optics", _widgets.OpticsWidget),
        ("calibrate", _widgets.CalibrateWidget),
        ("operators", _widgets.OperatorsWidget),
        ("reconstruct", _widgets.ReconstructWidget),
    ):
        out[name] = cls(viewer)
        viewer.window.add_dock_widget(out[name], name=name)
    return out


def _setup_bead(viewer, qtbot, optics):
    w = _steps.prepare_bead(viewer, qtbot, _docks(viewer), optics, Z, DZ)
    w["operators"].stacks.value = True  # these tests look at the RL stacks and the PSF too
    w["reconstruct"].iterations.value, w["reconstruct"].alpha.value = ITER, 0.0  # α 0: the method's default
    return w


def test_end_to_end_bead(make_napari_viewer, qtbot, bead, errors):
    frame, flat, white, optics = bead
    viewer = make_napari_viewer()
    w = _setup_bead(viewer, qtbot, optics)
    cal_layer = viewer.layers["PMMA bead white EI circles"]
    assert len(cal_layer.data) == 32 and "PMMA bead white EI centres" in viewer.layers
    assert "pitch" in w["calibrate"].result.value

    w["operators"].run()
    _steps.wait_for(qtbot, w["operators"])
    assert w["operators"].status.value.startswith("built in") and "21 planes" in w["operators"].status.value
    rec_built = _widgets.session_for(viewer).built[1]

    first, texts = [], []  # the quick first answer, shown while 'tv' iterates, and what the tab said

    def shown_first(*args, show=w["reconstruct"]._first):
        texts.append(show(*args))
        return texts[-1]

    w["reconstruct"]._first = shown_first
    viewer.layers.events.inserted.connect(
        lambda e: e.value.name == "PMMA bead RI" and first.append(e.value.data.copy())
    )  # the first answer's layer arrives on a turn of its own; the answer replaces its data
    w["reconstruct"].run()
    _steps.wait_for(qtbot, w["reconstruct"])
    assert errors == []
    assert _widgets.session_for(viewer).built[1] is rec_built  # operators reused, not rebuilt
    ri = viewer.layers["PMMA bead RI"]
    assert ri.data.shape == (21, 145, 145)
    assert np.allclose(ri.scale, (DZ, optics.object_pixel_um, optics.object_pixel_um), rtol=2e-3)
    assert tuple(ri.axis_labels) == ("z", "y", "x") and ri.translate[0] == Z[0]
    assert ri.metadata["ssdpc"]["settings"]["rl"]["iterations"] == ITER

    # exactly what core gives on the same input
    cal = calibrate(white, optics)
    res = Reconstructor(run_config(optics, z=Z, dz=DZ, rl={"iterations": ITER}), cal, flat=flat).reconstruct(frame)
    assert np.array_equal(ri.data, res.ri)
    assert np.array_equal(ri.scale, res.voxel_um)
    [quick], [text] = first, texts  # the Tikhonov inverse 'tv' starts from, replaced in place by the 'tv' answer
    rec = Reconstructor(run_config(optics, z=Z, dz=DZ, rl={"iterations": ITER}), cal, flat=flat)
    assert np.array_equal(quick, rec.first_answer(frame).ri) and not np.array_equal(quick, ri.data)
    assert "first answer" in text and "first_answer" not in ri.metadata["ssdpc"]["settings"]
    # the bead (n 1.49 in 1.518) is visible: Δn < 0 at its centre (world origin)
    zc, yc, xc = np.round(ri.world_to_data((0.0, 0.0, 0.0))).astype(int)
    assert ri.data[zc, yc, xc] - optics.medium_index < -0.002
    # the inputs (sensor pixels) are hidden once the volume (µm) is there
    assert ri.visible and not viewer.layers["PMMA bead"].visible

    # rerun with more outputs: the RI layer is updated in place, new layers are named after the source
    n_layers = len(viewer.layers)
    w["reconstruct"].out_phase.value = True
    w["reconstruct"].iterations.value = ITER + 1
    w["reconstruct"].run()
    _steps.wait_for(qtbot, w["reconstruct"])
    ri.colormap = "viridis"  # a display choice of the user: kept on rerun
    w["reconstruct"].run()
    _steps.wait_for(qtbot, w["reconstruct"])
    assert viewer.layers["PMMA bead RI"] is ri and len(viewer.layers) == n_layers + 1
    assert ri.colormap.name == "viridis"
    assert ri.metadata["ssdpc"]["settings"]["rl"]["iterations"] == ITER + 1
    phase = viewer.layers["PMMA bead phase"]
    assert phase.data.shape == ri.data.shape and phase.colormap.name == "RdBu_r"

    # the PSF stack of one lenslet, in µm
    w["operators"].show_psf()
    _steps.wait_for(qtbot, w["operators"])
    rec = _widgets.session_for(viewer).built[1]
    first = rec.lenslets[0]  # the lenslet picker starts at the first lit lenslet
    psf = viewer.layers[f"lenslet ({first.row}, {first.col}) PSF"]
    k = 0
    assert np.array_equal(psf.data, rec.stacks.psf.kernels(rec.z_um)[k]) and psf.data.shape[0] == 21
    assert np.allclose(psf.scale, (DZ, rec.pixel_um, rec.pixel_um))
    assert errors == []


def test_time_series_gives_tzyx_layer(make_napari_viewer, qtbot, errors):
    optics = _sample_data.series_optics()
    flat, white = _sample_data.series_flat_white()
    series = _sample_data.series_array(prefetch=False)[:2]  # the sample series' first 2 frames (lazy; 0 ships)
    viewer = make_napari_viewer()
    viewer.add_image(white, name="white")
    viewer.add_image(flat, name="flat")
    raw = viewer.add_image(series, name="cells", axis_labels=("t", "y", "x"))
    w = _docks(viewer)
    w["optics"].set_optics(optics)
    w["calibrate"].image.value = viewer.layers["white"]
    w["calibrate"].run()
    _steps.wait_for(qtbot, w["calibrate"])
    w["operators"].calibration.value = viewer.layers["white EI circles"]
    w["operators"].z_min.value, w["operators"].z_max.value, w["operators"].dz.value = Z[0], Z[1], DZ
    rc = w["reconstruct"]
    rc.raw.value, rc.flat.value, rc.iterations.value, rc.alpha.value = raw, viewer.layers["flat"], ITER, 0.0
    rc.frames.value = "all frames"
    rc.run()
    _steps.wait_for(qtbot, rc)
    assert errors == []
    ri = viewer.layers["cells RI"]
    assert ri.data.shape == (2, 21, 145, 145) and tuple(ri.axis_labels) == ("t", "z", "y", "x")
    assert ri.scale[0] == 1.0 and ri.scale[1] == DZ
    assert "t" in viewer.dims.axis_labels
    # frame 1 is the core's reconstruction of frame 1 in the series (warm-started from frame 0)
    cal = calibrate(white, optics)
    config = run_config(optics, z=Z, dz=DZ, rl={"iterations": ITER})
    rec = Reconstructor(config, cal, flat=flat)
    sink = MemorySink(keep=lambda res: res.ri)
    Pipeline(Job(config, cal, flat), reconstructor=rec).run(np.asarray(series), sink, progress=False)
    assert np.array_equal(ri.data[1], sink.frames[1])
    assert not np.array_equal(ri.data[0], ri.data[1])  # the sample moves


def test_cancel_stops_a_running_reconstruction(make_napari_viewer, qtbot, bead, errors):
    frame, flat, white, optics = bead
    viewer = make_napari_viewer()
    w = _setup_bead(viewer, qtbot, optics)
    rc = w["reconstruct"]
    rc.iterations.value = 500  # the most the settings allow: minutes of RL if not stopped
    reports = []
    worker = rc.run()
    worker.yielded.connect(lambda r: isinstance(r, tuple) and reports.append(r))  # progress, not the first answer
    qtbot.waitUntil(lambda: any(r[2].startswith("RL") for r in reports), timeout=_steps.WORKER_TIMEOUT_MS)
    t0 = time.perf_counter()
    rc.cancel_button.native.click()  # the Cancel button
    _steps.wait_for(qtbot, rc)
    stopped_s = time.perf_counter() - t0
    rl = [r for r in reports if r[2].startswith("RL")]
    assert rl[-1][0] < rl[-1][1] / 10  # far from the end of the 4 x 500 iterations
    assert stopped_s < 10.0, f"took {stopped_s:.1f} s to stop"
    assert rc.status.value == "cancelled" and "PMMA bead RI" not in viewer.layers
    assert rc.run_button.enabled and not rc.cancel_button.enabled
    assert errors == []


def test_core_errors_are_notifications(make_napari_viewer, qtbot, bead, errors, monkeypatch):
    frame, flat, white, optics = bead
    warned = []
    monkeypatch.setattr(_notify, "warning", lambda msg: warned.append(str(msg)))
    viewer = make_napari_viewer()
    w = _setup_bead(viewer, qtbot, optics)
    assert warned == []
    # a core warning raised in the worker thread: calibrating on the flat frame (σ < 1)
    w["calibrate"].image.value = viewer.layers["PMMA bead flat"]
    w["calibrate"].run()
    _steps.wait_for(qtbot, w["calibrate"])
    assert len(warned) == 1 and warned[0].startswith("flat frame (σ = 0.75, 24 lit lenslets)")
    # a frame that does not match the calibration
    viewer.add_image(frame[:512, :768], name="cropped")
    w["reconstruct"].raw.value = viewer.layers["cropped"]
    w["reconstruct"].run()
    _steps.wait_for(qtbot, w["reconstruct"])
    assert len(errors) == 1 and "differs from the calibration" in errors[0]
    assert "\n" not in errors[0] and "cropped RI" not in viewer.layers
    # sigma >= 1 in the optics editor
    w["optics"].fields["condenser_na"].value = 0.5
    assert len(errors) == 2 and "condenser_na 0.5 >= objective NA 0.4" in errors[1]
    assert _widgets.session_for(viewer).optics.condenser_na == optics.condenser_na  # bad edit not applied
    assert w["optics"].design.value.startswith("⚠")


def test_operators_z_boxes_take_the_settings_ranges(make_napari_viewer):
    ow = _widgets.OperatorsWidget(make_napari_viewer())
    rec = ReconstructionSettings()
    for box, name in ((ow.z_min, "z_min_um"), (ow.z_max, "z_max_um"), (ow.dz, "dz_um")):
        assert (box.min, box.max) == field_range(ReconstructionSettings, name), name
        assert box.value == getattr(rec, name), name


def test_optics_widget_design_numbers_are_live(make_napari_viewer, tmp_path):
    viewer = make_napari_viewer()
    ow = _widgets.OpticsWidget(viewer)
    viewer.window.add_dock_widget(ow)
    assert "FOV 122.5 µm" in ow.design.value and "R_xy 3.90 µm" in ow.design.value
    assert "32 in the pupil" in ow.design.value
    ow.fields["fourier_lens_mm"].value = 150.0  # twice the Fourier lens: M_EI halves, FOV doubles
    d = design(_widgets.session_for(viewer).optics)
    assert _widgets.session_for(viewer).optics.fourier_lens_mm == 150.0
    assert d["fov_um"] == pytest.approx(2 * 122.55, rel=1e-3) and f"FOV {d['fov_um']:.1f} µm" in ow.design.value
    p = tmp_path / "optics.yaml"
    ow.save(p)
    ow.set_optics(Optics.paper())
    ow.path.value = p
    ow.load()
    assert ow.fields["fourier_lens_mm"].value == 150.0
    # the paper's condenser NA 0.1: few lenslets straddle the source edge, and the widget says what it costs
    ow.set_optics(Optics.paper())
    assert "⚠ only 4 lenslets straddle the source edge" in ow.design.value
    ow.fields["condenser_na"].value = 0.3  # sigma 0.75: the outer rings straddle it
    d = design(_widgets.session_for(viewer).optics)
    assert "⚠" not in ow.design.value and f"axial FWHM {d['expected_axial_fwhm_um']:.1f} µm" in ow.design.value


def test_manual_calibration_from_guide_points(make_napari_viewer, qtbot, bead, errors):
    """The manual path: points clicked near a few EI centres (3 px off), or the EI centres of a
    calibration dragged in the viewer, guide the calibration, which refines to the same lattice."""
    frame, flat, white, optics = bead
    viewer = make_napari_viewer()
    w = _setup_bead(viewer, qtbot, optics)  # calibrated automatically on the white frame
    auto = w["calibrate"].calibration
    cw = w["calibrate"]
    points = cw.add_guide_points()
    assert cw.guide.value is points and points.mode == "add" and np.allclose(points.scale, cw.image.value.scale)
    rng = np.random.default_rng(3)
    picked = auto.centres_px[[5, 9, 14, 20, 26]] + rng.uniform(-3, 3, (5, 2))  # (x, y) px
    points.data = picked[:, ::-1]  # the points layer sits on the frame: data = (row, col)
    cw.run()
    _steps.wait_for(qtbot, cw)
    guided = cw.calibration
    assert errors == [] and guided is not auto and guided.kind_evidence["guided"]
    assert np.abs(guided.centres_px - auto.centres_px).max() < 0.05
    assert np.hypot(*(np.subtract(guided.grid.axis_px, auto.grid.axis_px))) < 0.05
    # a calibration's own centres layer as the guide (its optical-axis point is left out)
    cw.guide.value = viewer.layers["PMMA bead white EI centres"]
    cw.run()
    _steps.wait_for(qtbot, cw)
    assert errors == [] and np.abs(cw.calibration.centres_px - auto.centres_px).max() < 0.05
    # an empty guide layer is refused with the fix
    cw.guide.value = cw.add_guide_points()
    assert cw.run() is None and "holds no points" in errors[-1]


def test_a_shapes_layer_bounds_the_multislice_region(make_napari_viewer):
    """A rectangle drawn in a Shapes layer (µm, the layers' frame) is the region of the nonlinear
    model in the settings the dock hands down; an empty layer is a one-line error."""
    from napari_ssdpc.errors import SsdpcError

    viewer = make_napari_viewer()
    rw = _widgets.ReconstructWidget(viewer)
    assert rw.region.value is None and "multislice" not in rw.settings_changes()
    shapes = viewer.add_shapes([[[-10.0, -20.0], [-10.0, 30.0], [15.0, 30.0], [15.0, -20.0]]], name="region")
    shapes.translate = (1.0, 2.0)
    rw.reset_choices()
    rw.region.value = shapes
    assert rw.settings_changes()["multislice"]["roi_um"] == [-18.0, 32.0, -9.0, 16.0]
    assert _widgets.session_for(viewer).settings().multislice.roi_um == [-18.0, 32.0, -9.0, 16.0]
    rw.region.value = viewer.add_shapes(name="empty")
    with pytest.raises(SsdpcError, match="holds no shape: draw the region"):
        rw.settings_changes()
