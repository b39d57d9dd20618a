"""A live source in the Reconstruct tab: a recording followed while a camera writes it, the RI layer
growing in place from the store, the latency shown, Cancel and a rerun that recomputes nothing."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify

Z, DZ = (-10.0, 10.0), 5.0  # a coarse grid: 5 planes
FRAMES, PAUSE_S = 4, 0.5


def _camera(path, frames, pause_s):
    """A writer thread appending one TIFF page every ``pause_s``."""
    import tifffile

    def run():
        for f in frames:
            tifffile.imwrite(path, f, append=True, photometric="minisblack")
            time.sleep(pause_s)

    thread = threading.Thread(target=run)
    thread.start()
    return thread


def test_a_recording_being_written_grows_the_layer_and_a_rerun_recomputes_nothing(
    make_napari_viewer, qtbot, monkeypatch, tmp_path
):
    from napari_ssdpc.io.ome_zarr import read_ome_zarr
    from napari_ssdpc.io.store import done_frames
    from napari_ssdpc.pipeline.run import Pipeline
    from napari_ssdpc.pipeline.sinks import MemorySink

    viewer, w, frames, shown = _steps.live_bead_dock(make_napari_viewer, qtbot, monkeypatch, FRAMES, Z, DZ)
    rc = w["reconstruct"]
    raw, store = tmp_path / "camera.tif", tmp_path / "live.zarr"
    rc.store.value, rc.live.recording.value, rc.live.idle.value = store, raw, 1.5
    growth = []  # the RI layer's time points each time it changes
    worker = rc.live.start()  # before the camera has started: it waits for the file
    assert worker is not None and not rc.live.button.enabled
    qtbot.wait(300)
    camera = _camera(raw, frames, PAUSE_S)
    viewer.layers.events.inserted.connect(
        lambda e: (
            e.value.name == "live RI" and e.value.events.data.connect(lambda _: growth.append(e.value.data.shape[0]))
        )
    )
    _steps.wait_for(qtbot, rc)
    camera.join()
    assert shown == [] and rc.live.button.enabled
    assert list(done_frames(store)) == list(range(FRAMES))
    assert "4 new frames, 4 in all (0 done before)" in rc.status.value and "to layer shown" in rc.status.value
    assert sorted(rc.live.written_s) == sorted(rc.live.shown_s) == list(range(FRAMES))
    written, seen = np.array(list(rc.live.written_s.values())), np.array(list(rc.live.shown_s.values()))
    assert (written > 0).all() and (seen >= written).all() and seen.max() < 30
    # the layer grew in place as frames finished, and holds every frame
    ri = viewer.layers["live RI"]
    assert growth and growth == sorted(growth) and ri.data.shape[:2] == (FRAMES, 5)
    assert np.isfinite(np.asarray(ri.data)).all()
    # each time point is the core's volume of that frame (the same job, warm-started frame after frame)
    job, rec = rc.session.built
    core = MemorySink(keep=lambda res: res.ri)
    Pipeline(job, reconstructor=rec).run(np.stack(frames), core, progress=False)
    for t in range(FRAMES):
        np.testing.assert_array_equal(np.asarray(ri.data[t]), core.frames[t])
    assert not np.array_equal(core.frames[0], core.frames[1])

    # a rerun on the finished recording: every frame is already in the store, nothing is recomputed
    chunks = {p: p.stat().st_mtime_ns for p in (store / "ri" / "0").rglob("*") if p.is_file()}
    rc.live.idle.value = 0.5
    rc.live.start()
    _steps.wait_for(qtbot, rc)
    assert shown == [] and rc.live.written_s == {}
    assert "0 new frames, 4 in all (4 done before)" in rc.status.value
    assert {p: p.stat().st_mtime_ns for p in chunks} == chunks
    assert read_ome_zarr(store, "ri")[0].shape[0] == FRAMES

    # Cancel while waiting for frames that do not come: stopped at once, the store untouched
    rc.live.idle.value = 600.0
    rc.live.start()
    qtbot.waitUntil(lambda: rc.live.source is not None, timeout=10_000)
    start = time.monotonic()
    rc.cancel_button.native.click()
    _steps.wait_for(qtbot, rc)
    assert time.monotonic() - start < 5 and rc.status.value == "cancelled" and rc.live.button.enabled
    assert rc._watch is None and list(done_frames(store)) == list(range(FRAMES))


def test_following_needs_a_recording_and_a_store(make_napari_viewer, monkeypatch, tmp_path):
    from napari_ssdpc._napari.widgets.reconstruct import ReconstructWidget

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    rc = ReconstructWidget(make_napari_viewer())
    assert rc.live.start() is None and "choose the recording to follow" in shown[-1]
    rc.live.recording.value = tmp_path / "camera.tif"
    assert rc.live.start() is None and "'series to'" in shown[-1]
