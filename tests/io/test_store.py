"""Series stores: identity stamp, lock, killed creation, a fault at every write, completeness.

A small stand-in Reconstructor (8 x 8 volumes) keeps these tests fast; the real one is tested
in test_series.py.
"""

import errno
import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import zarr.storage._local as zlocal

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.frame_source import StoredFrames
from napari_ssdpc.io.ome_zarr import read_ome_zarr
from napari_ssdpc.io.store import done_frames, read_complete
from napari_ssdpc.io.store_lock import StoreLock
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import ZarrSink
from napari_ssdpc.reconstruction.checks import check_result
from napari_ssdpc.reconstruction.frame_result import Result
from napari_ssdpc.settings.config import RunConfig


class FakeRec:
    """A Reconstructor's contract in small: (2, 8, 8) volumes with Δn = frame mean / 1e6, checked
    before they are returned."""

    z_um = np.array([0.0, 1.0])
    y_um = x_um = (np.arange(8) - 3.5) * 0.5
    build_seconds = 0.0
    optics = None

    def settings(self):
        return {"dz_um": 1.0}

    def volume(self, frame):
        return np.full((2, 8, 8), float(np.mean(frame)) / 1e6, np.float32)

    def reconstruct(self, frame, *, warm=None, progress=None, should_stop=None, name="frame"):
        v = self.volume(frame)
        check_result(v, self.optics, name=f"volume of {name}")
        grid = dict(z_um=self.z_um, y_um=self.y_um, x_um=self.x_um, settings=self.settings())
        return Result(ri=1.5 + v, delta_n=v, phase=v, absorption=None, dpc={}, stacks={}, **grid)


@pytest.fixture(scope="module")
def setup(synthetic_series):
    optics, cal, flat, frames, _ = synthetic_series
    FakeRec.optics = optics
    return Job(RunConfig.of(optics, dz_um=1.0), cal), frames[:3]


def run(job, frames, out, rec=None, **kw):
    return Pipeline(job, reconstructor=rec or FakeRec()).run(frames, ZarrSink(out, ["phase"]), progress=False, **kw)


def tree_sha(folder):
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(str(p.relative_to(folder)).encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def dead_pid():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_changed_input_is_refused_naming_both_recordings(setup, tmp_path):
    recipe, frames = setup
    out = tmp_path / "s.zarr"
    run(recipe, frames, out, stop_after=2)
    before = tree_sha(out)
    other = frames.copy()
    other[2] += 1  # a new recording: only a frame not yet read differs
    with pytest.raises(SsdpcError, match=r"another recording: it was made from array \(3 frames.*sha256 \w{12}\)"):
        run(recipe, other, out)
    assert tree_sha(out) == before
    run(recipe, frames, out)  # the same recording resumes
    assert list(done_frames(out)) == [0, 1, 2]


def test_a_changed_file_is_refused_and_a_touched_one_resumes(setup, tmp_path):
    import tifffile

    recipe, frames = setup
    src, out = tmp_path / "in.tif", tmp_path / "s.zarr"
    tifffile.imwrite(src, frames, photometric="minisblack")
    run(recipe, StoredFrames(src), out, stop_after=1)
    os.utime(src)  # touched, same content
    run(recipe, StoredFrames(src), out, stop_after=1)
    tifffile.imwrite(src, frames[::-1], photometric="minisblack")
    with pytest.raises(SsdpcError, match=f"another recording.*{src.name}.*bytes, modified"):
        run(recipe, StoredFrames(src), out)
    assert list(done_frames(out)) == [0, 1]


@pytest.mark.parametrize("nth", range(1, 40, 3))
def test_a_fault_at_every_store_write_leaves_done_frames_right_and_a_rerun_completes(setup, tmp_path, monkeypatch, nth):
    """A full disk at the n-th file write (metadata, chunks, done marks): a one-line error, every
    frame marked done holds its right values, and a rerun completes the store."""
    recipe, frames = setup
    ref = tmp_path / "ref.zarr"
    run(recipe, frames, ref)
    out = tmp_path / "s.zarr"
    real, calls = zlocal._put, {"n": 0}

    def put(path, value, *a, **k):
        calls["n"] += 1
        if calls["n"] == nth:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, value, *a, **k)

    monkeypatch.setattr(zlocal, "_put", put)
    try:
        run(recipe, frames, out)
        failed = False
    except SsdpcError as e:
        assert "no space left" in str(e) and "\n" not in str(e)
        failed = True
    monkeypatch.undo()
    assert failed or calls["n"] < nth
    if out.exists():
        for name in ("ri", "phase"):
            got, want = read_complete(out, name), read_ome_zarr(ref, name)[0][:]
            for t in done_frames(out):
                np.testing.assert_array_equal(got[t], want[t])
    run(recipe, frames, out)
    for name in ("ri", "phase"):
        np.testing.assert_array_equal(read_ome_zarr(out, name)[0][:], read_ome_zarr(ref, name)[0][:])
    assert not list(tmp_path.glob(".s.zarr*")) and not list(out.rglob("*.partial"))


def test_a_killed_first_metadata_write_does_not_block_reruns(setup, tmp_path):
    recipe, frames = setup
    out = tmp_path / "s.zarr"
    out.mkdir()
    (out / ".zgroup").write_text('{"zarr_format": 2}')
    (out / ".zattrs.3f2a.partial").write_text('{"ssdpc')  # zarr's temporary file, killed
    stale = tmp_path / f".s.zarr.{dead_pid()}.new"  # a creation killed before its rename
    stale.mkdir()
    (stale / ".zgroup").write_text("{}")
    run(recipe, frames, out)
    assert list(done_frames(out)) == [0, 1, 2] and not stale.exists()
    assert not list(out.rglob("*.partial"))


def test_a_foreign_folder_or_file_is_refused_untouched(setup, tmp_path):
    recipe, frames = setup
    foreign = tmp_path / "other.zarr"
    foreign.mkdir()
    (foreign / "data.txt").write_text("another program's data")
    before = tree_sha(foreign)
    with pytest.raises(SsdpcError, match="not written by `ssdpc reconstruct`"):
        run(recipe, frames, foreign)
    assert tree_sha(foreign) == before and sorted(p.name for p in foreign.iterdir()) == ["data.txt"]
    afile = tmp_path / "x.zarr"
    afile.write_bytes(b"a file")
    with pytest.raises(SsdpcError, match="is a file, not an OME-Zarr folder"):
        run(recipe, frames, afile)
    assert afile.read_bytes() == b"a file"


_HOLD = """
import sys, time
from napari_ssdpc.io.store_lock import StoreLock
with StoreLock(sys.argv[1]):
    print("held", flush=True)
    time.sleep(60)
"""


def test_one_writer_per_store_and_a_stale_lock_is_taken_over(setup, tmp_path):
    recipe, frames = setup
    out = tmp_path / "s.zarr"
    lock = tmp_path / ".s.zarr.lock"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    holder = subprocess.Popen([sys.executable, "-c", _HOLD, str(out)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert holder.stdout.readline().strip() == "held"  # a live writer
        with pytest.raises(SsdpcError, match=f"being written by process {holder.pid}"):
            run(recipe, frames, out)
        assert not out.exists()
    finally:
        holder.kill()
        holder.wait()
    assert lock.read_text() == str(holder.pid)  # left by a killed writer: taken over
    run(recipe, frames, out)
    assert list(done_frames(out)) == [0, 1, 2] and not lock.exists()
    for stale in ("", str(dead_pid()), str(os.getppid()), "garbage"):  # no OS lock held: free
        lock.write_text(stale)
        with StoreLock(out):
            assert lock.read_text() == str(os.getpid())
            with pytest.raises(SsdpcError, match="being written by"):  # a second writer, even in this process
                StoreLock(out).__enter__()
        assert not lock.exists()


def _race(out, k, rounds, barrier, held, stale):
    """One of several processes: each round, all try to take the store's lock at once."""
    for r in range(rounds):
        if k == 0:  # a stale lock left for the round: empty, a dead writer's PID, or garbage
            Path(f"{out.parent}/.{out.name}.lock").write_text(stale[r % len(stale)])
        barrier.wait()
        lock = StoreLock(out)
        try:
            lock.__enter__()
            with held.get_lock():
                held[r] += 1
            mine = True
        except SsdpcError:
            mine = False
        barrier.wait()  # everyone has tried while the holder still holds it
        if mine:
            lock.__exit__(None, None, None)
        barrier.wait()


def test_exactly_one_of_many_processes_racing_for_a_stale_lock_holds_it(tmp_path):
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    n, rounds = 5, 40
    barrier, held = ctx.Barrier(n), ctx.Array("i", rounds)
    stale = ["", str(dead_pid()), "12x", ""]
    out = tmp_path / "s.zarr"
    procs = [ctx.Process(target=_race, args=(out, k, rounds, barrier, held, stale)) for k in range(n)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    assert [p.exitcode for p in procs] == [0] * n
    assert list(held) == [1] * rounds


def test_the_reader_shows_frames_not_marked_done_as_nan(setup, tmp_path):
    import zarr

    recipe, frames = setup
    out = tmp_path / "s.zarr"
    run(recipe, frames, out)
    root = zarr.open_group(str(out), mode="r+")
    root["ssdpc_done"][1] = 0  # as if killed between frame 1's chunks
    ri = read_complete(out, "ri")
    assert np.isnan(ri[1]).all() and np.isfinite(ri[[0, 2]]).all()
    # napari's reader stays lazy and shows the same: no frame with RI but without its phase
    from napari_ssdpc._napari.reader import get_result_reader

    layers = {kw["metadata"]["ssdpc"]["quantity"]: data for data, kw, _ in get_result_reader(str(out))(str(out))}
    assert set(layers) == {"ri", "phase"}
    for data in layers.values():
        shown = np.asarray(data)
        assert data.shape == (3, 2, 8, 8) and np.isnan(shown[1]).all() and np.isfinite(shown[[0, 2]]).all()


def test_the_napari_writer_never_writes_into_a_series_or_a_foreign_store(setup, tmp_path):
    import zarr

    from napari_ssdpc._napari.writer import write_result

    recipe, frames = setup
    series = tmp_path / "s.zarr"
    run(recipe, frames, series)
    foreign = tmp_path / "other.zarr"
    zarr.open_group(str(foreign), mode="w").create_array("img", shape=(4, 4), dtype="uint8")
    plain = tmp_path / "plain.zarr"
    plain.mkdir()
    (plain / "notes.txt").write_text("mine")
    vol = np.zeros((2, 8, 8), np.float32)
    refused = {series: "time series written by ssdpc reconstruct", foreign: "did not write", plain: "did not write"}
    for store, words in refused.items():
        before = tree_sha(store)
        with pytest.raises(SsdpcError, match=words):
            write_result(store, vol, voxel_um=(1, 1, 1), info={"quantity": "phase"})
        assert tree_sha(store) == before, store.name
    assert not list(tmp_path.glob(".*part"))
    empty = tmp_path / "empty.zarr"  # an empty folder holds nothing to lose
    empty.mkdir()
    write_result(empty, vol, voxel_um=(1, 1, 1), info={"quantity": "ri"})
    write_result(empty, vol + 1, voxel_um=(1, 1, 1), info={"quantity": "phase"})  # a second layer: ours, kept
    assert sorted(k for k in zarr.open_group(str(empty), mode="r").group_keys()) == ["phase", "ri"]


@pytest.mark.parametrize("value, words", [(np.nan, "NaN/inf"), (9e12, "beyond any sample")])
def test_an_unphysical_frame_is_not_written(setup, tmp_path, value, words):
    recipe, frames = setup

    class Bad(FakeRec):
        def volume(self, frame):
            v = super().volume(frame)
            v[0, 0, 0] = value
            return v

    out = tmp_path / "s.zarr"
    with pytest.raises(SsdpcError, match=f"array frame 0 .*{words}"):
        run(recipe, frames, out, rec=Bad())
    assert list(done_frames(out)) == [] and np.isnan(read_complete(out, "ri")).all()


def test_a_store_is_an_ngff_image_at_its_root_with_units_scale_and_translation(tmp_path):
    """NGFF readers that look only at the root (ome-zarr-py, napari-ome-zarr, Fiji) find the RI volume,
    with µm units, its voxel size and the position of its first voxel; each quantity keeps its group."""
    import zarr

    from napari_ssdpc.io.ome_zarr import create_ome_zarr

    out = tmp_path / "s.zarr"
    create_ome_zarr(out, "ri", (3, 5, 8, 9), "TZYX", (2.0, 0.5, 0.5), origin_um=(-4.0, -1.75, -2.0))
    create_ome_zarr(out, "opd_nm", (3, 8, 9), "TYX", (2.0, 0.5, 0.5), origin_um=(-4.0, -1.75, -2.0))
    root = zarr.open_group(str(out), mode="r")
    ms = root.attrs["multiscales"][0]
    assert ms["datasets"][0]["path"] == "ri/0" and root["ri/0"].shape == (3, 5, 8, 9)
    assert [a.get("unit") for a in ms["axes"]] == [None, "micrometer", "micrometer", "micrometer"]
    scale, shift = ms["datasets"][0]["coordinateTransformations"]
    assert scale["scale"] == [1.0, 2.0, 0.5, 0.5] and shift["translation"] == [0.0, -4.0, -1.75, -2.0]
    opd = root["opd_nm"].attrs["multiscales"][0]  # a 2D map: (t, y, x), one chunk per frame
    assert opd["datasets"][0]["coordinateTransformations"][0]["scale"] == [1.0, 0.5, 0.5]
    assert root["opd_nm/0"].chunks == (1, 8, 9)
