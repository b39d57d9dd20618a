"""Following a recording as it is written: a TIFF appended page by page, a growing OME-Zarr image,
a folder of TIFF files; every frame once, resumed like a series, bad frames named."""

import threading
import time

import numpy as np
import pytest
import tifffile
import zarr

from napari_ssdpc.cli.main import main
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.io.followed import FollowedFrames
from napari_ssdpc.io.ome_zarr import read_ome_zarr
from napari_ssdpc.io.store import done_frames

CLI = ["--z", "-20", "20", "--dz", "10", "--iterations", "2", "--method", "rl"]


@pytest.fixture(scope="module")
def data(synthetic_series, tmp_path_factory):
    optics, cal, flat, frames, _ = synthetic_series
    d = tmp_path_factory.mktemp("follow")
    tifffile.imwrite(d / "flat.tif", flat)
    cal.to_json(d / "cal.json")
    return d, frames


def _plain(d, raw, out):
    inputs = ["--calibration", str(d / "cal.json"), "--flat", str(d / "flat.tif")]
    return ["reconstruct", str(raw), *inputs, *CLI, "-o", str(out)]


def _args(d, raw, out, idle=2.0):
    return _plain(d, raw, out) + ["--follow", "--idle", str(idle)]


def _errors(capsys):
    """The error lines on stderr (besides progress and notes); no traceback."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return [line for line in err.splitlines() if line.startswith("ssdpc: error:")]


def _camera(write, frames, pause_s=0.4):
    """A writer thread: one frame every ``pause_s``."""

    def run():
        for k, f in enumerate(frames):
            write(k, f)
            time.sleep(pause_s)

    thread = threading.Thread(target=run)
    thread.start()
    return thread


def test_a_tiff_being_written_is_followed_and_a_rerun_adds_only_new_frames(data, tmp_path, capsys):
    d, frames = data
    raw, out = tmp_path / "rec.tif", tmp_path / "out.zarr"
    camera = _camera(lambda k, f: tifffile.imwrite(raw, f, append=True, photometric="minisblack"), frames[:4])
    time.sleep(0.1)  # the first page is on disk before the follower starts
    assert main(_args(d, raw, out)) == 0
    camera.join()
    err = capsys.readouterr().err
    assert "4 frames followed; latency from frame on disk to result" in err
    assert list(done_frames(out)) == [0, 1, 2, 3]
    ri = read_ome_zarr(out, "ri")[0]
    assert ri.shape[0] == 4 and np.isfinite(ri[:]).all()
    # the same frames read from the finished file, alone: the same volumes
    whole = tmp_path / "whole.zarr"
    assert main(_plain(d, raw, whole)) == 0
    np.testing.assert_array_equal(read_ome_zarr(whole, "ri")[0][:], ri[:])
    # the recording goes on: a rerun resumes, writes only the new frames and grows the store
    before = {p.name: p.stat().st_mtime_ns for p in (out / "ri" / "0").iterdir() if p.name[0].isdigit()}
    for f in frames[4:6]:
        tifffile.imwrite(raw, f, append=True, photometric="minisblack")
    assert main(_args(d, raw, out, idle=0.5)) == 0
    after = {p.name: p.stat().st_mtime_ns for p in (out / "ri" / "0").iterdir() if p.name[0].isdigit()}
    assert {k: after[k] for k in before} == before  # finished frames untouched
    assert list(done_frames(out)) == list(range(6)) and read_ome_zarr(out, "ri")[0].shape[0] == 6


def test_another_recording_at_the_same_path_is_refused(data, tmp_path, capsys):
    d, frames = data
    raw, out = tmp_path / "rec.tif", tmp_path / "out.zarr"
    tifffile.imwrite(raw, frames[:2], photometric="minisblack")
    assert main(_args(d, raw, out, idle=0.3)) == 0
    tifffile.imwrite(raw, frames[5:7], photometric="minisblack")  # a new recording under the old name
    capsys.readouterr()
    assert main(_args(d, raw, out, idle=0.3)) == 2
    errors = _errors(capsys)
    assert len(errors) == 1 and "holds frames of another recording" in errors[0]
    assert list(done_frames(out)) == [0, 1]


def test_a_frame_of_another_size_stops_the_run_naming_it_and_keeps_what_was_written(data, tmp_path, capsys):
    d, frames = data
    folder, out = tmp_path / "frames", tmp_path / "out.zarr"
    folder.mkdir()
    for k in range(2):
        tifffile.imwrite(folder / f"img_{k:04d}.tif", frames[k])
    tifffile.imwrite(folder / "img_0002.tif", frames[2][:-8])  # a camera ROI changed mid-recording
    assert main(_args(d, folder, out, idle=0.5)) == 2
    errors = _errors(capsys)
    assert len(errors) == 1 and "frame 2" in errors[0]
    assert list(done_frames(out)) == [0, 1]


def test_a_gap_in_a_numbered_folder_is_named(data, tmp_path):
    _, frames = data
    for k in (0, 1, 3):
        tifffile.imwrite(tmp_path / f"img_{k:04d}.tif", frames[k])
    with pytest.warns(SsdpcWarning, match="file number 2 is missing between 1 and 3"):
        src = FollowedFrames(tmp_path, idle_s=0.5, settle_s=0.0)
    assert src.available() == 3
    np.testing.assert_array_equal(src[2], frames[3])


def test_a_growing_ome_zarr_image_counts_a_frame_once_it_is_complete(data, tmp_path):
    _, frames = data
    path = tmp_path / "camera.zarr"
    root = zarr.open_group(str(path), mode="w", zarr_format=2)
    shape = frames.shape[1:]
    root.attrs["multiscales"] = [{"version": "0.4", "datasets": [{"path": "0"}], "axes": []}]
    a = root.create_array("0", shape=(1, *shape), chunks=(1, *shape), dtype="uint16")
    a[0] = frames[0]
    src = FollowedFrames(path, idle_s=5.0, settle_s=0.3)
    assert src.frame_shape == shape and src.available() == 1 and not src.finished()
    a.resize((2, *shape))  # the writer announced frame 1 and is writing it
    assert src.available() == 1  # not settled yet
    a[1] = frames[1]
    assert src.available() == 1  # just written: the follower sees it change
    time.sleep(0.4)
    assert src.available() == 2  # unchanged for settle_s: complete
    np.testing.assert_array_equal(src[1], frames[1])
    assert set(src.identity()) >= {"path", "followed", "sha256"} and src.identity()["followed"]


def test_follow_refuses_what_it_cannot_do(data, tmp_path, capsys):
    d, frames = data
    raw = tmp_path / "rec.tif"
    tifffile.imwrite(raw, frames[0])
    for argv, fix in (
        (_args(d, raw, tmp_path / "one.ome.tif"), "give -o OUT.zarr"),
        (_args(d, raw, tmp_path / "a.zarr", idle=-1), "--idle must be a positive number"),
        (_args(d, tmp_path / "notes.txt", tmp_path / "b.zarr"), "does not exist"),
    ):
        assert main(argv) == 2
        errors = _errors(capsys)
        assert len(errors) == 1 and fix in errors[0]
    (tmp_path / "empty").mkdir()
    with pytest.raises(SsdpcError, match="no complete frame arrived within 0.3 s"):
        FollowedFrames(tmp_path / "empty", idle_s=0.3)


def test_a_tiff_rewritten_during_the_run_is_never_mixed_in(data, tmp_path):
    """A new recording written over the followed TIFF from its start: with more frames the first
    read after it stops the run (frame 0 changed), with fewer the next look does (it shrank)."""
    _, frames = data
    raw = tmp_path / "rec.tif"
    tifffile.imwrite(raw, frames[:3], photometric="minisblack")
    src = FollowedFrames(raw, idle_s=5.0, settle_s=0.0)
    assert src.available() == 3 and all(np.array_equal(src[t], frames[t]) for t in range(3))
    tifffile.imwrite(raw, frames[5:9], photometric="minisblack")  # another recording, longer
    assert src.available() == 4
    with pytest.raises(SsdpcError, match="frame 0 changed while frame 3 was read: another recording"):
        src[3]
    tifffile.imwrite(raw, frames[:3], photometric="minisblack")
    src = FollowedFrames(raw, idle_s=5.0, settle_s=0.0)
    assert src.available() == 3
    tifffile.imwrite(raw, frames[5:6], photometric="minisblack")  # another recording, shorter
    with pytest.raises(SsdpcError, match="shrank from 3 to 1 frames"):
        src.available()


def test_a_folder_whose_files_change_places_stops_instead_of_shifting_frames(data, tmp_path):
    _, frames = data
    for k in (0, 2):
        tifffile.imwrite(tmp_path / f"img_{k:04d}.tif", frames[k])
    with pytest.warns(SsdpcWarning, match="file number 1 is missing"):
        src = FollowedFrames(tmp_path, idle_s=5.0, settle_s=0.0)
    assert src.available() == 2
    tifffile.imwrite(tmp_path / "img_0001.tif", frames[1])  # arrives late, with a lower number
    with pytest.raises(SsdpcError, match="frame 1 was img_0002.tif and is now img_0001.tif"):
        src.available()
    (tmp_path / "img_0001.tif").unlink()
    src = FollowedFrames(tmp_path, idle_s=5.0, settle_s=0.0)
    assert src.available() == 2
    (tmp_path / "img_0000.tif").unlink()  # deleted
    with pytest.raises(SsdpcError, match="shrank from 2 to 1 frames"):
        src.available()


def test_a_recording_that_does_not_exist_yet_is_waited_for_within_the_idle_time(data, tmp_path):
    """The CLI and napari wait alike: for the path to appear, then for its first frame."""
    _, frames = data
    raw = tmp_path / "later.tif"
    threading.Timer(0.5, lambda: tifffile.imwrite(raw, frames[:1], photometric="minisblack")).start()
    src = FollowedFrames(raw, idle_s=5.0, settle_s=0.0)
    assert src.available() == 1 and np.array_equal(src[0], frames[0])
    with pytest.raises(SsdpcError, match="does not exist and did not appear within 0.3 s"):
        FollowedFrames(tmp_path / "never.tif", idle_s=0.3)


def test_a_zarr_image_that_claims_more_frames_than_it_holds_gives_the_ones_written(data, tmp_path):
    _, frames = data
    path = tmp_path / "claims.zarr"
    root = zarr.open_group(str(path), mode="w", zarr_format=2)
    shape = frames.shape[1:]
    a = root.create_array("0", shape=(10**9, *shape), chunks=(1, *shape), dtype="uint16", fill_value=0)
    a[0], a[1] = frames[0], frames[1]
    root.attrs["multiscales"] = [{"version": "0.4", "datasets": [{"path": "0"}], "axes": []}]
    src = FollowedFrames(path, idle_s=5.0, settle_s=0.0)
    assert src.available() == 2  # not 10⁹ frames of fill values
    np.testing.assert_array_equal(src[1], frames[1])


def test_an_empty_or_half_written_file_in_a_folder_is_waited_for_then_named(data, tmp_path, capsys):
    d, frames = data
    folder = tmp_path / "frames"
    folder.mkdir()
    tifffile.imwrite(folder / "img_0000.tif", frames[0])
    (folder / "img_0001.tif").write_bytes(b"")  # created by the camera, not written yet
    tifffile.imwrite(folder / "img_0002.tif", frames[2])
    src = FollowedFrames(folder, idle_s=5.0, settle_s=0.0)
    assert src.available() == 1 and not src.finished()  # frame 1 is waited for, frame 2 not taken in its place
    whole = (folder / "img_0002.tif").read_bytes()
    (folder / "img_0001.tif").write_bytes(whole[: len(whole) // 2])  # half written
    assert src.available() == 1
    tifffile.imwrite(folder / "img_0001.tif", frames[1])
    assert src.available() == 3 and np.array_equal(src[1], frames[1]) and np.array_equal(src[2], frames[2])
    # a file that stays empty: named once the idle time has passed; the frames before it are stored
    (folder / "img_0003.tif").write_bytes(b"")
    out = tmp_path / "out.zarr"
    assert main(_args(d, folder, out, idle=0.5)) == 2
    errors = _errors(capsys)
    assert len(errors) == 1 and "img_0003.tif (frame 3) is empty or incomplete" in errors[0]
    assert list(done_frames(out)) == [0, 1, 2]
