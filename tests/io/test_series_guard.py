"""A series is checked frame by frame before each frame is marked done: a bad later frame and an
input rewritten in place during the run stop it with one line, and the frames marked done stay
those of the recording the store names."""

import os

import numpy as np
import pytest
import tifffile

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.frame_source import StoredFrames
from napari_ssdpc.io.ome_zarr import read_ome_zarr
from napari_ssdpc.io.store import done_frames
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import ZarrSink
from napari_ssdpc.settings.config import RunConfig

from .test_store import FakeRec


def _run(job, frames, out, rec=None):
    return Pipeline(job, reconstructor=rec or FakeRec()).run(frames, ZarrSink(out, ["phase"]), progress=False)


@pytest.fixture(scope="module")
def job(synthetic_series):
    optics, cal, flat, frames, _ = synthetic_series
    FakeRec.optics = optics
    return Job(RunConfig.of(optics, z_min_um=0, z_max_um=0, dz_um=2.0), cal, flat), frames[:3]


class Rewriter(FakeRec):
    """Reconstructs like FakeRec and, while frame ``at`` is being reconstructed, copies another
    recording over the input file (``cp other.tif series.tif``)."""

    def __init__(self, src, other, at, keep_time=False):
        self.src, self.other, self.at, self.n, self.keep_time = src, other, at, 0, keep_time

    def reconstruct(self, frame, **kw):
        if self.n == self.at:
            st = self.src.stat()
            self.src.write_bytes(self.other.read_bytes())
            if self.keep_time:  # cp -p of a file of the same size: size and modification time as before
                os.utime(self.src, ns=(st.st_atime_ns, st.st_mtime_ns))
        self.n += 1
        return super().reconstruct(frame, **kw)


@pytest.mark.parametrize("keep_time", [False, True], ids=["cp", "cp-p"])
@pytest.mark.parametrize("at", [0, 1, 2])
def test_an_input_rewritten_during_the_run_stops_it(job, tmp_path, at, keep_time):
    recipe, frames = job
    src, other, out = tmp_path / "series.tif", tmp_path / "other.tif", tmp_path / "s.zarr"
    tifffile.imwrite(src, frames, photometric="minisblack")
    tifffile.imwrite(other, frames[::-1] + 7, photometric="minisblack")
    assert other.stat().st_size == src.stat().st_size
    with pytest.raises(SsdpcError, match=f"series.tif changed during the run .* frame {at} was not marked done") as e:
        _run(recipe, StoredFrames(src), out, Rewriter(src, other, at, keep_time))
    assert "\n" not in str(e.value)
    assert list(done_frames(out)) == list(range(at))  # only frames read from the first recording
    ref = tmp_path / "ref.zarr"  # the frames kept are the first recording's
    _run(recipe, frames, ref)
    for t in done_frames(out):
        np.testing.assert_array_equal(read_ome_zarr(out, "ri")[0][t], read_ome_zarr(ref, "ri")[0][t])
    with pytest.raises(SsdpcError, match="another recording"):  # the new content is not resumed into it
        _run(recipe, StoredFrames(src), out)


def test_a_touched_input_resumes_and_is_checked_against_its_new_time(job, tmp_path):
    recipe, frames = job
    src, out = tmp_path / "series.tif", tmp_path / "s.zarr"
    tifffile.imwrite(src, frames, photometric="minisblack")
    Pipeline(recipe, reconstructor=FakeRec()).run(
        StoredFrames(src), ZarrSink(out, ["phase"]), progress=False, stop_after=1
    )
    os.utime(src, ns=(1_000_000_000, 1_000_000_000))  # same content, another time: resumes
    _run(recipe, StoredFrames(src), out)
    assert list(done_frames(out)) == [0, 1, 2]


@pytest.mark.parametrize(
    "bad, words",
    [
        (lambda f, w: np.zeros_like(f), "every pixel is 0"),
        (lambda f, w: np.random.default_rng(3).integers(0, 4096, f.shape).astype(f.dtype), "no light in the directly"),
        (lambda f, w: w, "as on a white frame"),
        (lambda f, w: np.roll(f, 6, axis=1), "elemental images sit"),
    ],
    ids=["zero", "noise", "white", "camera-moved"],
)
def test_every_frame_of_a_series_is_checked_before_it_is_marked_done(synthetic_series, job, tmp_path, bad, words):
    recipe, frames = job
    white = synthetic_series[4]
    series = frames.copy()
    series[1] = bad(frames[1], white)
    src, out = tmp_path / "series.tif", tmp_path / "s.zarr"
    tifffile.imwrite(src, series, photometric="minisblack")
    with pytest.raises(SsdpcError, match=f"series.tif frame 1.*{words}") as e:
        _run(recipe, StoredFrames(src), out, recipe.build())
    assert "\n" not in str(e.value) and list(done_frames(out)) == [0]
