"""Atomic single files and file sets: a fault at every write point leaves the old files intact."""

import errno
import hashlib
import os
import subprocess
import sys

import numpy as np
import pytest
import tifffile

from napari_ssdpc import files
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import atomic_write, clean_stale_parts
from napari_ssdpc.io.frames import read_frame, write_ome_tiff, write_ome_tiffs, write_tiff
from napari_ssdpc.io.paths import check_outputs, same_file


def sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def dead_pid():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_atomic_write_replaces_only_on_success(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_write(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("killed")
    assert target.read_text() == "old" and not list(tmp_path.glob(".*.part"))
    with atomic_write(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new"


@pytest.mark.parametrize("point", ["write", "fsync", "replace-1", "replace-2"])
def test_a_fault_at_every_write_point_of_a_set_keeps_the_old_set(tmp_path, monkeypatch, point):
    """Two OME-TIFFs over an earlier pair: a full disk at each write point leaves both old files
    (checksums), and a rerun writes both new ones."""
    a, b = tmp_path / "out.ome.tif", tmp_path / "out_phase.ome.tif"
    old = {a: (np.zeros((2, 4, 4), "f4"), "ZYX", None, None), b: (np.ones((2, 4, 4), "f4"), "ZYX", None, None)}
    write_ome_tiffs(old)
    before = {a: sha(a), b: sha(b)}
    new = {a: (np.full((2, 4, 4), 5, "f4"), "ZYX", None, None), b: (np.full((2, 4, 4), 6, "f4"), "ZYX", None, None)}
    full = OSError(errno.ENOSPC, "No space left on device")
    calls = {"n": 0}
    if point == "write":
        real = tifffile.imwrite

        def imwrite(path, *a_, **k):
            calls["n"] += 1
            if calls["n"] == 2:  # the second file
                raise full
            return real(path, *a_, **k)

        monkeypatch.setattr(tifffile, "imwrite", imwrite)
    elif point == "fsync":
        monkeypatch.setattr(files, "_fsync", lambda p: (_ for _ in ()).throw(full))
    else:
        real_replace = os.replace
        k = int(point[-1])

        def replace(src, dst):
            calls["n"] += 1
            if calls["n"] == k:
                raise full
            return real_replace(src, dst)

        monkeypatch.setattr(files.os, "replace", replace)
    with pytest.raises(SsdpcError, match="no space left"):
        write_ome_tiffs(new)
    monkeypatch.undo()
    if point != "replace-2":  # nothing renamed yet
        assert {p: sha(p) for p in before} == before
    else:  # the first rename went through: the rerun below still gives a consistent set
        assert sha(b) == before[b]
    assert not list(tmp_path.glob(".*.part"))
    write_ome_tiffs(new)
    assert tifffile.imread(a)[0, 0, 0] == 5 and tifffile.imread(b)[0, 0, 0] == 6


def test_a_killed_writer_leaves_a_part_file_that_the_next_write_removes(tmp_path):
    target = tmp_path / "frame.tif"
    stale = tmp_path / f".frame.tif.{dead_pid()}.abc123.part"
    stale.write_bytes(b"half a frame")
    alive = tmp_path / f".frame.tif.{os.getppid()}.def456.part"  # a running writer: left alone
    alive.write_bytes(b"in progress")
    write_tiff(target, np.zeros((16, 16), "u2"))
    assert not stale.exists() and alive.exists()
    assert clean_stale_parts(target) == []
    assert read_frame(target).shape == (16, 16)


def test_file_system_faults_are_one_line_errors(tmp_path, monkeypatch):
    (tmp_path / "dir.ome.tif").mkdir()
    with pytest.raises(SsdpcError, match="is a folder"):
        write_ome_tiff(tmp_path / "dir.ome.tif", np.zeros((2, 4, 4)), axes="ZYX")
    with pytest.raises(SsdpcError, match="does not exist"):
        write_tiff(tmp_path / "nodir" / "f.tif", np.zeros((4, 4)))

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    old = tmp_path / "keep.tif"
    write_tiff(old, np.arange(16, dtype="u2").reshape(4, 4))
    before = sha(old)
    monkeypatch.setattr(tifffile, "imwrite", full)
    with pytest.raises(SsdpcError, match="disk full .no space left on the device.; free some space"):
        write_tiff(old, np.zeros((4, 4)))
    assert sha(old) == before and not list(tmp_path.glob(".*.part"))

    def short(*a, **k):  # numpy's tofile on a full disk: no errno
        raise OSError("105125 requested and 24520 written")

    monkeypatch.setattr(tifffile, "imwrite", short)
    with pytest.raises(SsdpcError, match=f"writing {old}: disk full"):
        write_tiff(old, np.zeros((4, 4)))
    assert sha(old) == before and not list(tmp_path.glob(".*.part"))
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        try:
            with pytest.raises(SsdpcError, match="not writable"):
                check_outputs({"output": ro / "x.tif"}, {})
        finally:
            ro.chmod(0o755)


def test_outputs_are_compared_with_inputs_after_resolving(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    raw = tmp_path / "raw.tif"
    raw.write_bytes(b"raw")
    (tmp_path / "link.tif").symlink_to(raw)
    assert same_file("./raw.tif", raw) and same_file("link.tif", raw)
    for out in ("raw.tif", "./raw.tif", "link.tif", str(raw)):
        with pytest.raises(SsdpcError, match="would overwrite the raw frame"):
            check_outputs({"output": out}, {"raw frame": "raw.tif"})
    with pytest.raises(SsdpcError, match="the overlay would be written over the calibration"):
        check_outputs({"calibration": "cal.png", "overlay": "cal.png"}, {})
    (tmp_path / "mine.png").write_bytes(b"holiday photo")
    with pytest.raises(SsdpcError, match="did not write.*--overwrite"):
        check_outputs({"calibration": "mine.json", "overlay": "mine.png"}, {})
    check_outputs({"calibration": "mine.json", "overlay": "mine.png"}, {}, overwrite=True)
    assert raw.read_bytes() == b"raw" and (tmp_path / "mine.png").read_bytes() == b"holiday photo"
    # the main output too: a user's own TIFF or JSON of that name is never replaced without --overwrite
    for name, content in (("user.ome.tif", b"II*\x00 a user's image"), ("user.tif", b"II*\x00"), ("c.json", b"{}")):
        (tmp_path / name).write_bytes(content)
        with pytest.raises(SsdpcError, match=rf"the output {name} would replace a file napari-ssdpc did not write"):
            check_outputs({"output": name}, {})
        assert (tmp_path / name).read_bytes() == content


@pytest.mark.parametrize("frames", [1, 3])
def test_a_half_truncated_tiff_is_refused_by_both_readers(tmp_path, frames):
    from napari_ssdpc.io.frame_source import StoredFrames

    a = np.arange(frames * 64 * 80, dtype="u2").reshape(frames, 64, 80).squeeze()
    full, half = tmp_path / "full.tif", tmp_path / "half.tif"
    tifffile.imwrite(full, a, photometric="minisblack")
    half.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    with pytest.raises(SsdpcError, match="complete TIFF"):
        read_frame(half)
    with pytest.raises(SsdpcError, match="truncated"):
        StoredFrames(half)
    np.testing.assert_array_equal(StoredFrames(full)[frames - 1], a if frames == 1 else a[-1])
