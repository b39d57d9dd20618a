"""Frames from a Micro-Manager core (pymmcore-plus's pure-Python camera, no hardware): every frame
of an acquisition into the loop, the acquisition never held back, dropped frames counted."""

import threading
import time

import numpy as np
import pytest

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import MemorySink

unicore = pytest.importorskip("pymmcore_plus.experimental.unicore", reason="pymmcore-plus is not installed")
useq = pytest.importorskip("useq", reason="useq-schema (with pymmcore-plus) is not installed")

from camera_sim import core_with, series  # noqa: E402
from napari_ssdpc.pipeline.camera import CoreFrames  # noqa: E402

from .test_frame_loop import CountingRec, job  # noqa: E402, F401


class SlowRec(CountingRec):
    """A solver that takes 60 ms a frame (4 x the camera's period)."""

    def reconstruct(self, frame, **kw):
        time.sleep(0.06)
        return super().reconstruct(frame, **kw)


def _every_frame(job):  # noqa: F811
    shape = tuple(job.calibration.frame_shape)
    core = core_with(series(shape, 6))
    frames, rec, sink = CoreFrames(core, maxsize=None), CountingRec(), MemorySink()
    watchdog = threading.Timer(30.0, frames.close)  # frames that never arrive end the run, not the test session
    watchdog.start()
    acquisition = core.run_mda(useq.MDASequence(time_plan={"interval": 0, "loops": 6}))  # started elsewhere
    report = Pipeline(job, reconstructor=rec).run(frames, sink, progress=False)
    acquisition.join()
    watchdog.cancel()
    assert report.written == 6 and report.dropped == [] and rec.seen == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert frames.finished()  # ended by the acquisition's end


def test_every_frame_of_an_acquisition_on_the_core_is_reconstructed(job):  # noqa: F811
    _every_frame(job)


def test_a_core_with_qt_signals_delivers_frames_to_a_loop_that_blocks_the_gui_thread(job, qapp):  # noqa: F811
    """In a Qt application (napari-micromanager's core) the core's signals are Qt signals: the frames
    still reach a frame loop run on the GUI thread, whose event loop is not turning."""
    from pymmcore_plus._util import signals_backend

    assert signals_backend() == "qt"
    _every_frame(job)


def test_a_lagging_solver_never_holds_the_acquisition_back(job):  # noqa: F811
    shape = tuple(job.calibration.frame_shape)
    core = core_with(series(shape, 40))
    frames, rec, sink = CoreFrames(core, maxsize=2), SlowRec(), MemorySink()
    acquisition = core.run_mda(useq.MDASequence(time_plan={"interval": 0, "loops": 40}))
    report = Pipeline(job, reconstructor=rec).run(frames, sink, progress=False)
    acquisition.join()
    # the solver takes 60 ms a frame, the camera 15 ms: the oldest waiting frames are dropped, and
    # every frame the camera made reached the source (the acquisition ran to its end)
    assert report.frames == 40 and report.written + len(report.dropped) == 40 and report.dropped
    assert 40.0 in rec.seen and rec.seen == sorted(rec.seen)  # the last frame kept, the order kept
    assert frames.held() <= 1


def test_a_core_without_a_camera_or_a_frame_of_another_shape_is_one_line(job):  # noqa: F811
    with pytest.raises(SsdpcError, match="load and set a camera device"):
        CoreFrames(unicore.UniMMCore())
    shape = tuple(job.calibration.frame_shape)
    core = core_with(series(shape, 2))
    frames = CoreFrames(core)
    frames._on_frame(np.zeros((4, 4), np.uint16))
    with pytest.raises(SsdpcError, match="keep the camera ROI and binning fixed"):
        Pipeline(job, reconstructor=CountingRec()).run(frames, MemorySink(), progress=False)


def test_a_camera_run_into_a_store_records_the_frames_kept_and_dropped(job, tmp_path):  # noqa: F811
    import zarr

    from napari_ssdpc.io.live_store import LIVE
    from napari_ssdpc.io.store import done_frames, read_complete
    from napari_ssdpc.pipeline.sinks import ZarrSink

    shape = tuple(job.calibration.frame_shape)
    core = core_with(series(shape, 30))
    out = tmp_path / "live.zarr"
    frames, rec = CoreFrames(core, maxsize=2), SlowRec()
    acquisition = core.run_mda(useq.MDASequence(time_plan={"interval": 0, "loops": 30}))
    report = Pipeline(job, reconstructor=rec).run(frames, ZarrSink(out), progress=False)
    acquisition.join()
    live = zarr.open_group(str(out), mode="r").attrs[LIVE]
    kept = [t for a, b in live["kept"] for t in range(a, b + 1)]
    dropped = [t for a, b in live["dropped"] for t in range(a, b + 1)]
    assert live["frames"] == 30 and live["maxsize"] == 2 and dropped == report.dropped and dropped
    assert kept == done_frames(out).tolist() and sorted(kept + dropped) == list(range(30))
    ri = read_complete(out)  # a dropped frame is NaN, a kept one holds its frame's volume (mean k + 1)
    assert np.isnan(ri[dropped[0]]).all() and np.allclose(ri[kept[-1]], 1.5 + (kept[-1] + 1) * 1e-3)
    # a second acquisition into the same store would mix two acquisitions: refused, the store unchanged
    with pytest.raises(SsdpcError, match="a live acquisition writes a new store"):
        Pipeline(job, reconstructor=rec).run(CoreFrames(core_with(series(shape, 2))), ZarrSink(out), progress=False)
    assert done_frames(out).tolist() == kept
