"""The workflow as a user meets it: the ssDPC dock opened from napari's Plugins menu.

napari hands a plugin dock widget its own proxy of the viewer. The dock's tabs and any widget a
script makes on the viewer must still share one session: the optics set in one, the calibration
made in another and the reconstruction in a third.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify
from napari_ssdpc._napari import sample_data as _sample_data
from napari_ssdpc._napari import widgets as _widgets
from napari_ssdpc._napari.widgets import session as _session
from napari_ssdpc.physics.design import design

Z, DZ = (-10.0, 10.0), 2.0
FIRST_WINDOW = (1089, 633)  # napari's first window on a 1280 x 800 screen, px


def _dock_tabs(viewer):
    """The ssDPC dock opened from the Plugins menu: its tabs as 'optics', 'calibrate', 'operators', ..."""
    _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    w = {k.lower(): v for k, v in dock.tabs.items()}
    w["operators"] = w["method"]
    return dock, w


def test_the_plugins_menu_holds_the_dock_the_measurements_and_the_second_front_end():
    """The dock holds every step of the light-field workflow; two entries measure (results over time,
    beads fitted as spheres); one takes a conventional DPC stack, which has none of the dock's steps
    (no calibration, no flat)."""
    from npe2 import PluginManifest

    import napari_ssdpc

    manifest = PluginManifest.from_file(Path(napari_ssdpc.__file__).parent / "napari.yaml")
    names = [w.display_name for w in manifest.contributions.widgets]
    assert names == [
        "ssDPC",
        "Objects over time",
        "Beads (each fitted as a sphere)",
        "DPC stack (LED array, segmented condenser)",
    ]


def test_every_dock_of_the_plugin_open_at_once_fits_a_laptop_screen(make_napari_viewer, qtbot):
    """The ssDPC dock, Objects over time, Beads and DPC stack open together: the docks scroll, the
    window stays within a 1280 x 800 screen (the objects' table and plots made it 989 px tall)."""
    viewer = make_napari_viewer(show=True)
    window = viewer.window._qt_window
    window.resize(1280, 800)
    for name in (
        "ssDPC",
        "Objects over time",
        "Beads (each fitted as a sphere)",
        "DPC stack (LED array, segmented condenser)",
    ):
        viewer.window.add_plugin_dock_widget("napari-ssdpc", name)
        qtbot.wait(100)
        size = window.size()
        assert (size.width(), size.height()) == (1280, 800), (name, size.width(), size.height())


def test_the_dock_and_widgets_made_by_a_script_share_one_session_and_reach_an_ri_volume(
    make_napari_viewer, qtbot, monkeypatch
):
    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer()
    dock, w = _dock_tabs(viewer)  # napari hands the dock a proxy of the viewer
    for name, cls in (("operators", _widgets.OperatorsWidget), ("reconstruct", _widgets.ReconstructWidget)):
        w[name] = cls(viewer)  # a script's widgets, on the viewer itself
        viewer.window.add_dock_widget(w[name], name=name)
    sessions = {id(x.session) for x in w.values() if hasattr(x, "session")}
    assert len(sessions) == 1  # one model for the viewer, whatever proxy each widget was given
    assert dock.session is _widgets.session_for(viewer)

    frame, flat, white, optics = _sample_data.bead_frames()
    _steps.prepare_bead(viewer, qtbot, w, optics, Z, DZ)  # the optics are set in Optics, read by the others
    assert _widgets.session_for(viewer).optics is w["calibrate"].session.optics
    w["operators"].sign.value, w["operators"].tv_iterations.value = "lighter", 30  # PMMA in oil: lighter
    w["reconstruct"].run()
    _steps.wait_for(qtbot, w["reconstruct"])
    assert shown == []
    ri = viewer.layers["PMMA bead RI"]
    assert ri.data.shape[0] == 11 and np.allclose(ri.scale[0], DZ)
    settings = ri.metadata["ssdpc"]["settings"]
    assert settings["method"] == "tv" and settings["tv_sign"] == "lighter" and settings["tv_iterations_run"] <= 30
    # the axial resolution is shown with the result: 24 µm expected at condenser NA 0.3
    assert ri.metadata["ssdpc"]["axial_fwhm_um"] == pytest.approx(design(optics)["expected_axial_fwhm_um"])
    assert "axial resolution ≈ 24 µm" in w["reconstruct"].status.value
    lo, hi = ri.contrast_limits  # symmetric about the medium, spanning the bead: none of it clipped
    assert hi - optics.medium_index == pytest.approx(optics.medium_index - lo)
    assert lo <= float(ri.data.min()) + 1e-7
    assert ri.data.max() <= optics.medium_index + 1e-6  # the sign constraint holds: nowhere denser
    assert np.allclose(ri.scale[1:], optics.object_pixel_um, rtol=2e-3)
    # the bead (n 1.49 in 1.518) at the world origin: Δn < 0 there
    zc, yc, xc = np.round(ri.world_to_data((0.0, 0.0, 0.0))).astype(int)
    assert ri.data[zc, yc, xc] - optics.medium_index < -0.002


def test_the_ssdpc_dock_runs_the_workflow_and_fits_a_laptop_screen(make_napari_viewer, qtbot, monkeypatch, tmp_path):
    """The one dock from the Plugins menu: its tabs are the shared widgets, its settings file is the
    one the command line reads, and at napari's first window size it leaves the canvas 450 px or more."""
    from napari_ssdpc._napari.placement import scale_bar
    from napari_ssdpc._napari.widgets.dock import DOCK_WIDTH_PX, SsdpcDock
    from napari_ssdpc.settings.config import RunConfig

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer(show=True)
    window = viewer.window._qt_window
    window.resize(*FIRST_WINDOW)
    dock, w = _dock_tabs(viewer)
    assert isinstance(dock, SsdpcDock) and dock.session is _widgets.session_for(viewer)
    qtbot.wait(200)
    size = window.size()
    assert (size.width(), size.height()) == FIRST_WINDOW  # the dock fits: the window did not grow
    canvas = viewer.window._qt_viewer.canvas.native.width()
    assert dock.width() <= DOCK_WIDTH_PX + 20 and canvas >= 450, (dock.width(), canvas)  # was 430 and 362
    bar = dock.tab_widget.tabBar()  # every step in view (a 300 px strip on top hid 3 of the 7)
    assert all(bar.rect().contains(bar.tabRect(i)) for i in range(bar.count())), [bar.tabRect(i) for i in range(7)]
    frame, flat, white, optics = _sample_data.bead_frames()
    _steps.prepare_bead(viewer, qtbot, w, optics, Z, DZ)
    w["operators"].sign.value, w["operators"].tv_iterations.value = "lighter", 25
    w["reconstruct"].iterations.value = 7

    path = dock.save_settings(tmp_path / "run.yaml")
    cfg = RunConfig.from_yaml(path)  # what `ssdpc reconstruct --config run.yaml` reads
    rec = cfg.reconstruction
    assert (rec.z_min_um, rec.z_max_um, rec.dz_um) == (Z[0], Z[1], DZ)
    assert (rec.tv.sign, rec.tv.iterations, rec.rl.iterations) == ("lighter", 25, 7)
    assert cfg.optics.condenser_na == optics.condenser_na == 0.3

    w["operators"].z_min.value, w["operators"].sign.value, w["reconstruct"].iterations.value = -40.0, "any", 3
    assert dock.load_settings(path)
    assert (w["operators"].z_min.value, w["operators"].sign.value, w["reconstruct"].iterations.value) == (
        Z[0],
        "lighter",
        7,
    )
    assert not dock.load_settings(tmp_path / "missing.yaml") and "missing.yaml" in shown[-1]
    shown.clear()

    w["reconstruct"].run()
    _steps.wait_for(qtbot, w["reconstruct"])
    assert shown == []
    ri = viewer.layers["PMMA bead RI"]
    assert ri.data.shape[0] == 11 and ri.metadata["ssdpc"]["settings"]["tv_sign"] == "lighter"
    # one world in µm: raw frames (at the object-space pixel) and calibration overlays beside the volume
    assert {str(u) for lyr in viewer.layers for u in lyr.units[-2:]} == {"micrometer"}
    raw = viewer.layers["PMMA bead"]
    assert np.allclose(raw.scale, optics.object_pixel_um) and scale_bar(viewer).visible
    circles = viewer.layers["PMMA bead white EI circles"]
    assert np.allclose(circles.scale, raw.scale) and np.allclose(circles.translate, raw.translate)
    # the run was remembered: a new dock in a new viewer starts from it
    assert RunConfig.from_yaml(_session.remembered_settings_path()).reconstruction.tv.iterations == 25


def test_a_series_streams_to_ome_zarr_and_is_shown_from_disk(make_napari_viewer, qtbot, monkeypatch, tmp_path):
    """'all frames' with a store: every frame is written as it finishes (the resumable writer of the
    command line) and the RI layer is read back from disk, never held in memory as a whole."""
    import zarr

    from napari_ssdpc._napari.placement import scale_bar
    from napari_ssdpc.io.store import done_frames

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer()
    _, w = _dock_tabs(viewer)
    frame, flat, white, optics = _sample_data.bead_frames()
    _steps.prepare_bead(viewer, qtbot, w, optics, Z, DZ)
    viewer.add_image(np.stack([frame, frame, frame]), name="bead series", axis_labels=("t", "y", "x"))
    w["operators"].sign.value, w["operators"].tv_iterations.value = "lighter", 10
    rc = w["reconstruct"]
    rc.raw.value, rc.frames.value, rc.store.value = viewer.layers["bead series"], "all frames", tmp_path / "bead.zarr"
    rc.run()
    _steps.wait_for(qtbot, rc)
    assert shown == [] and sorted(done_frames(tmp_path / "bead.zarr")) == [0, 1, 2]
    ri = viewer.layers["bead RI"]
    # the first result, although streamed from disk: inputs hidden, view on the volume, scale bar in µm
    assert not viewer.layers["bead series"].visible and not viewer.layers["PMMA bead"].visible
    assert ri.visible and scale_bar(viewer).visible
    assert ri.data.shape[:2] == (3, 11) and not isinstance(ri.data, np.ndarray)  # lazy, from the store
    assert np.asarray(ri.data).min() - optics.medium_index < -0.002  # the bead
    # every frame is the core's: the series solved by the same job, each frame warm-started from the last
    from napari_ssdpc.pipeline.run import Pipeline
    from napari_ssdpc.pipeline.sinks import MemorySink

    job, rec = rc.session.built
    core = MemorySink(keep=lambda res: res.ri)
    Pipeline(job, reconstructor=rec).run(np.stack([frame, frame, frame]), core, progress=False)
    for t in range(3):
        assert np.array_equal(np.asarray(ri.data[t]), core.frames[t])
    assert np.allclose(ri.scale[-3:], (DZ, optics.object_pixel_um, optics.object_pixel_um), rtol=2e-3)
    assert (
        zarr.open_group(str(tmp_path / "bead.zarr"), mode="r").attrs["multiscales"][0]["datasets"][0]["path"] == "ri/0"
    )
    rc.run()  # a rerun resumes: nothing left to do
    _steps.wait_for(qtbot, rc)
    assert shown == [] and "3 frames written" in rc.status.value
