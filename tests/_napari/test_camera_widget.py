"""The camera source in the Reconstruct tab: the frames of an acquisition on a Micro-Manager core
(pymmcore-plus's pure-Python camera) reconstructed as they arrive, the RI layer updated in place,
the store written with the frames kept and dropped, Stop between frames."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")
pytest.importorskip("pymmcore_plus.experimental.unicore", reason="pymmcore-plus is not installed")
useq = pytest.importorskip("useq", reason="useq-schema (with pymmcore-plus) is not installed")

import gui_steps as _steps  # noqa: E402
from camera_sim import core_with  # noqa: E402
from napari_ssdpc._napari import notify as _notify  # noqa: E402

Z, DZ = (-10.0, 10.0), 5.0  # a coarse grid: 5 planes
FRAMES = 4


def test_an_acquisition_on_the_core_is_reconstructed_live_into_the_layer_and_the_store(
    make_napari_viewer, qtbot, monkeypatch, tmp_path
):
    import zarr

    from napari_ssdpc.io.live_store import LIVE
    from napari_ssdpc.io.store import done_frames, read_complete
    from napari_ssdpc.pipeline.run import Pipeline
    from napari_ssdpc.pipeline.sinks import MemorySink

    viewer, w, frames, shown = _steps.live_bead_dock(make_napari_viewer, qtbot, monkeypatch, FRAMES, Z, DZ)
    core = core_with(frames)
    rc = w["reconstruct"]
    store = tmp_path / "camera.zarr"
    rc.store.value, rc.camera.queue.value = store, 0  # every frame kept: the store must be complete
    added = []  # the RI layers added: one, its data replaced in place by each newer volume the display shows
    viewer.layers.events.inserted.connect(lambda e: added.append(e.value.name))
    worker = rc.camera.start(core)
    assert worker is not None and rc.camera.button.text == "Stop the camera run"
    acquisition = core.run_mda(useq.MDASequence(time_plan={"interval": 0, "loops": FRAMES}))  # napari-micromanager's
    _steps.wait_for(qtbot, rc)
    acquisition.join()
    assert shown == [] and rc.camera.frames is None and rc.camera.button.text.startswith("Reconstruct the camera")
    assert f"{FRAMES} of {FRAMES} frames reconstructed, none dropped" in rc.status.value
    assert "to layer shown" in rc.status.value and len(rc.camera.reconstructed_s) == FRAMES
    assert 0 < min(rc.camera.reconstructed_s) and max(rc.camera.shown_s) < 60
    # the store holds every frame, each the core's volume of that camera frame; its metadata says so
    job, rec = rc.session.built
    core_ri = MemorySink(keep=lambda res: res.ri)
    Pipeline(job, reconstructor=rec).run(frames, core_ri, progress=False)
    assert list(done_frames(store)) == list(range(FRAMES))
    stored = read_complete(store)
    for t in range(FRAMES):
        np.testing.assert_allclose(stored[t], core_ri.frames[t], rtol=1e-6)
    assert zarr.open_group(str(store), mode="r").attrs[LIVE] == {
        "frames": FRAMES,
        "kept": [[0, FRAMES - 1]],
        "dropped": [],
        "maxsize": None,
    }
    # the layer is the newest volume, updated in place
    layer = viewer.layers["camera RI"]
    np.testing.assert_allclose(np.asarray(layer.data), core_ri.frames[FRAMES - 1], rtol=1e-6)
    assert layer.data.ndim == 3 and added.count("camera RI") == 1

    # Stop with no acquisition running: the run ends between frames, at once, the new store empty
    store2 = tmp_path / "stopped.zarr"
    rc.store.value, rc.camera.queue.value = store2, 2
    rc.camera.start(core)
    qtbot.wait(300)
    start = time.monotonic()
    rc.camera.button.native.click()  # "Stop the camera run"
    _steps.wait_for(qtbot, rc)
    assert shown == [] and time.monotonic() - start < 5 and "0 of 0 frames reconstructed" in rc.status.value
    assert zarr.open_group(str(store2), mode="r").attrs[LIVE]["frames"] == 0
    # into a store that holds an acquisition already: refused in one line, the store untouched
    rc.store.value = store
    rc.camera.start(core)
    _steps.wait_for(qtbot, rc)
    assert shown and "a live acquisition writes a new store" in shown[-1]
    assert list(done_frames(store)) == list(range(FRAMES))


def test_without_pymmcore_plus_the_camera_names_the_extra(make_napari_viewer, monkeypatch):
    import builtins

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    real_import = builtins.__import__

    def no_pymmcore(name, *args, **kwargs):
        if name.startswith("pymmcore_plus"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    viewer = make_napari_viewer()
    _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    monkeypatch.setattr(builtins, "__import__", no_pymmcore)
    assert dock.tabs["Reconstruct"].camera.start() is None
    assert shown == ["a camera needs pymmcore-plus: pip install 'napari-ssdpc[live]' (and napari-micromanager)"]
