"""The frame loop: any source (a file, an array, frames still arriving) into any sink, each frame
once, in order, with the previous frame's solution as a warm start where asked."""

import threading
import time

import numpy as np
import pytest

from napari_ssdpc.errors import Cancelled, SsdpcError
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import MemorySink, OmeTiffSink, ZarrSink
from napari_ssdpc.pipeline.sources import FrameSource, LiveFrames, as_source
from napari_ssdpc.reconstruction.frame_result import Result
from napari_ssdpc.reconstruction.methods.base import Solution
from napari_ssdpc.settings.config import RunConfig


class CountingRec:
    """A Reconstructor's contract in small: (2, 4, 4) volumes of the frame's mean; it records the
    frames it saw and the warm starts it was given."""

    z_um = np.array([0.0, 1.0])
    y_um = x_um = np.arange(4) * 0.5
    build_seconds = 0.0

    def __init__(self):
        self.seen, self.warm = [], []

    def settings(self):
        return {"dz_um": 1.0}

    def reconstruct(self, frame, *, warm=None, progress=None, should_stop=None, name="frame"):
        self.seen.append(float(np.mean(frame)))
        self.warm.append(None if warm is None else float(warm.phase.mean()))
        v = np.full((2, 4, 4), float(np.mean(frame)) * 1e-3, np.float32)
        grid = dict(z_um=self.z_um, y_um=self.y_um, x_um=self.x_um, settings=self.settings())
        return Result(v + 1.5, v, v, None, {}, {}, solution=Solution(v), **grid)


class ResumedSink(MemorySink):
    """A sink that already holds some frames (a store being resumed)."""

    def __init__(self, held):
        super().__init__()
        self.held = set(held)

    def _open(self, job, grid, source):
        return set(self.held)


@pytest.fixture(scope="module")
def job(synthetic_series):
    optics, cal, _, _, _ = synthetic_series
    return Job(RunConfig.of(optics), cal)


def test_live_frames_are_followed_as_they_arrive_until_the_source_closes(job):
    shape = tuple(job.calibration.frame_shape)
    live, rec, sink = LiveFrames(shape, maxsize=None), CountingRec(), MemorySink()
    assert isinstance(live, FrameSource) and as_source(live) is live
    arrivals = []

    def camera():
        for k in range(4):
            time.sleep(0.05)
            live.push(np.full(shape, k + 1, np.uint16))
        live.close()

    writer = threading.Thread(target=camera)
    writer.start()
    report = Pipeline(job, reconstructor=rec).run(
        live, sink, progress=False, on_frame=lambda t, done, total, res: arrivals.append((t, done, total))
    )
    writer.join()
    assert report.written == 4 and rec.seen == [1.0, 2.0, 3.0, 4.0]  # every frame once, in order
    assert arrivals == [(0, 1, None), (1, 2, None), (2, 3, None), (3, 4, None)]  # the length is not known
    assert sorted(sink.frames) == [0, 1, 2, 3] and sink.last.delta_n.mean() == pytest.approx(4e-3)
    with pytest.raises(SsdpcError, match="closed"):
        live.push(np.zeros(shape, np.uint16))
    with pytest.raises(SsdpcError, match="a frame of shape"):
        LiveFrames(shape).push(np.zeros((4, 4)))


class SlowRec(CountingRec):
    """A solver that takes 20 ms a frame."""

    def reconstruct(self, frame, **kw):
        time.sleep(0.02)
        return super().reconstruct(frame, **kw)


def test_a_lagging_solver_drops_the_oldest_waiting_frames_and_memory_stays_bounded(job):
    shape = tuple(job.calibration.frame_shape)
    live, rec, sink = LiveFrames(shape, maxsize=2), SlowRec(), MemorySink()
    held = []

    def camera():  # 60 frames 1 ms apart: far faster than the solver
        for k in range(60):
            live.push(np.full(shape, k + 1, np.uint16))
            held.append(live.held())
            time.sleep(0.001)
        live.close()

    writer = threading.Thread(target=camera)
    writer.start()
    report = Pipeline(job, reconstructor=rec).run(live, sink, progress=False)
    writer.join()
    assert max(held) <= 3  # two waiting and the one being solved, however many frames came
    assert report.written + len(report.dropped) == 60 and len(report.dropped) > 30
    kept = sorted(sink.frames)
    assert set(kept).isdisjoint(report.dropped) and 59 in kept  # the newest frame is never dropped
    assert rec.seen == [t + 1.0 for t in kept]  # each kept frame once, in order
    assert live.held() <= 1
    with pytest.raises(SsdpcError, match="maxsize"):
        LiveFrames(shape, maxsize=0)


def test_a_stop_ends_the_wait_for_the_next_live_frame(job):
    live, stop = LiveFrames(tuple(job.calibration.frame_shape)), threading.Event()
    threading.Timer(0.3, stop.set).start()
    t0 = time.perf_counter()
    with pytest.raises(Cancelled):
        Pipeline(job, reconstructor=CountingRec()).run(live, MemorySink(), progress=False, should_stop=stop.is_set)
    assert time.perf_counter() - t0 < 2.0


def test_warm_starts_hand_each_frame_the_previous_solution(job):
    frames = np.stack([np.full(job.calibration.frame_shape, k, np.uint16) for k in (10, 20, 30)])
    cold, warm = CountingRec(), CountingRec()
    Pipeline(job, reconstructor=cold).run(frames, MemorySink(), progress=False, warm_start=False)
    Pipeline(job, reconstructor=warm).run(frames, MemorySink(), progress=False)  # the configuration's default
    assert cold.warm == [None, None, None]
    assert warm.warm == [None, pytest.approx(0.01), pytest.approx(0.02)]


def test_a_frame_after_one_done_by_another_run_starts_cold(job):
    frames = np.stack([np.full(job.calibration.frame_shape, k, np.uint16) for k in (10, 20, 30, 40)])
    rec = CountingRec()
    Pipeline(job, reconstructor=rec).run(frames, ResumedSink({1}), progress=False, warm_start=True)
    assert rec.warm == [None, None, pytest.approx(0.03)]  # frames 0, 2 (cold: 1 was not solved here), 3


def test_sinks_refuse_sources_they_cannot_hold(job, tmp_path):
    shape = tuple(job.calibration.frame_shape)
    frames = np.zeros((2, *shape), np.uint16)
    with pytest.raises(SsdpcError, match="holds several frames; write a time series to OME-Zarr"):
        Pipeline(job, reconstructor=CountingRec()).run(frames, OmeTiffSink({"ri": tmp_path / "o.ome.tif"}))
    assert not (tmp_path / "o.ome.tif").exists()


def test_live_frames_grow_a_store_that_says_which_frames_it_kept(job, tmp_path):
    import zarr

    from napari_ssdpc.io.live_store import LIVE
    from napari_ssdpc.io.store import done_frames

    live = LiveFrames(tuple(job.calibration.frame_shape), maxsize=None)
    for k in (10, 20, 30):
        live.push(np.full(live.frame_shape, k, np.uint16))
    live.close()
    report = Pipeline(job, reconstructor=CountingRec()).run(live, ZarrSink(tmp_path / "s.zarr"), progress=False)
    assert report.written == 3 and list(done_frames(tmp_path / "s.zarr")) == [0, 1, 2]
    record = zarr.open_group(str(tmp_path / "s.zarr"), mode="r").attrs[LIVE]
    assert record == {"frames": 3, "kept": [[0, 2]], "dropped": [], "maxsize": None}
