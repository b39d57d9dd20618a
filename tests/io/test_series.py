"""Time series: streamed frames, (t, z, y, x) OME-Zarr, resume after a kill, Dask workers."""

import os
import signal
import subprocess
import sys
import time
import tracemalloc

import numpy as np
import pytest
import tifffile

from napari_ssdpc.backend import gpu_available
from napari_ssdpc.cli.main import main
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.frame_source import PagedSeries, StoredFrames
from napari_ssdpc.io.ome_zarr import read_ome_zarr
from napari_ssdpc.io.store import done_frames
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import ZarrSink
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.validation.cases import run_config

SETTINGS = dict(z=(-20.0, 20.0), dz=10.0, rl={"iterations": 2}, method="rl")
CLI = ["--z", "-20", "20", "--dz", "10", "--iterations", "2", "--method", "rl"]


@pytest.fixture(scope="module")
def data(synthetic_series):
    return synthetic_series[:4]


@pytest.fixture(scope="module")
def files(data, tmp_path_factory):
    optics, cal, flat, frames = data
    d = tmp_path_factory.mktemp("series")
    tifffile.imwrite(d / "series.tif", frames[:6], photometric="minisblack")
    tifffile.imwrite(d / "flat.tif", flat)
    cal.to_json(d / "cal.json")
    return d


@pytest.fixture(scope="module")
def recipe(data):
    optics, cal, flat, _ = data
    return Job(run_config(optics, **SETTINGS), cal, flat, stacks=True)


@pytest.fixture(scope="module")
def rec(recipe):
    return recipe.build()


@pytest.fixture(scope="module")
def serial(files, tmp_path_factory):
    """The uninterrupted serial run of the CLI, the reference for the other runs."""
    out = tmp_path_factory.mktemp("serial") / "out.zarr"
    assert main(_args(files, out) + ["--save", "phase,dpc"]) == 0
    return out


def _args(files, out):
    return (
        [
            "reconstruct",
            str(files / "series.tif"),
            "--calibration",
            str(files / "cal.json"),
            "--flat",
            str(files / "flat.tif"),
        ]
        + CLI
        + ["-o", str(out)]
    )


def _arrays(out, names=("ri", "phase", "dpc")):
    return {n: read_ome_zarr(out, n)[0][:] for n in names}


def test_series_store_holds_every_frame_as_reconstructed_alone(serial, data, rec):
    _, _, _, frames = data
    ri, voxel, attrs = read_ome_zarr(serial, "ri")
    assert ri.shape == (6, 5) + rec.mask.shape and ri.chunks == (1, 5) + rec.mask.shape  # one chunk per frame
    assert voxel == pytest.approx((10.0, rec.pixel_um, rec.pixel_um))
    assert attrs["settings"]["rl"]["iterations"] == 2 and attrs["quantity"] == "refractive index"
    assert list(done_frames(serial)) == list(range(6))
    for t in (0, 5):
        res = rec.reconstruct(frames[t])
        np.testing.assert_array_equal(ri[t], res.ri)
        np.testing.assert_array_equal(read_ome_zarr(serial, "dpc")[0][t], np.stack([res.dpc["ud"], res.dpc["lr"]]))


def test_rerun_skips_finished_frames_and_refuses_other_settings(serial, files, capsys):
    before = {p: p.stat().st_mtime_ns for p in (serial / "ri" / "0").iterdir()}
    capsys.readouterr()
    assert main(_args(files, serial) + ["--save", "phase,dpc"]) == 0
    assert "all 6 frames were already written" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in (serial / "ri" / "0").iterdir()} == before
    assert main(_args(files, serial) + ["--save", "phase,dpc", "--iterations", "3"]) == 2
    err = capsys.readouterr().err
    assert "other settings" in err and err.count("\n") == 1


def test_frames_are_streamed_not_loaded(data, recipe, rec, tmp_path):
    """Memory does not grow with the series length: 12 frames peak no higher than 2 frames
    (plus less than one frame), from a memory map or from compressed pages."""
    _, _, _, frames = data
    plain, packed = tmp_path / "plain.tif", tmp_path / "packed.tif"
    tifffile.imwrite(plain, frames, photometric="minisblack")
    tifffile.imwrite(packed, frames, photometric="minisblack", compression="zlib")
    assert isinstance(StoredFrames(plain)._open(), np.memmap)
    assert isinstance(StoredFrames(packed)._open(), PagedSeries)
    np.testing.assert_array_equal(StoredFrames(packed)[7], frames[7])
    peaks = {}
    for n in (2, 12):
        tracemalloc.start()
        sink = ZarrSink(tmp_path / f"out{n}.zarr")
        Pipeline(recipe, reconstructor=rec).run(packed, sink, progress=False, stop_after=n)
        peaks[n] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert list(done_frames(tmp_path / "out2.zarr")) == [0, 1]
    assert peaks[12] - peaks[2] < frames[0].nbytes, peaks


def test_killed_run_leaves_a_readable_store_and_resumes(serial, files, tmp_path):
    out = tmp_path / "killed.zarr"
    # the child holds after its first frame is written (as if the next frame were slow), so the kill
    # always lands mid-run
    hold = (
        "import sys, time\n"
        "from napari_ssdpc.pipeline import sinks\n"
        "write = sinks.write_frame\n"
        "def held(*a, **k):\n"
        "    s = write(*a, **k)\n"
        "    time.sleep(600)\n"
        "    return s\n"
        "sinks.write_frame = held\n"
        "from napari_ssdpc.cli.main import main\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", hold, *_args(files, out), "--save", "phase,dpc"], stderr=subprocess.DEVNULL
    )
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None:
            if (out / "ssdpc_done").is_dir() and len(done_frames(out)) >= 1:
                break
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)  # no clean-up at all
    finally:
        proc.wait()
    done = list(done_frames(out))
    assert done == [0]
    ref = _arrays(serial)
    got = _arrays(out)  # every chunk reads: nothing is corrupt
    for t in range(6):
        for n in ref:
            if t in done:
                np.testing.assert_array_equal(got[n][t], ref[n][t])
            else:  # not yet written (NaN) or written but not marked
                assert np.all(np.isnan(got[n][t])) or np.array_equal(got[n][t], ref[n][t])
    assert main(_args(files, out) + ["--save", "phase,dpc"]) == 0
    assert list(done_frames(out)) == list(range(6))
    assert not list(out.rglob("*.partial"))
    for n, a in _arrays(out).items():
        np.testing.assert_array_equal(a, ref[n])


def test_dask_local_cluster_of_two_workers_equals_the_serial_run(serial, files, tmp_path):
    pytest.importorskip("distributed")
    out = tmp_path / "dask.zarr"
    assert main(_args(files, out) + ["--save", "phase,dpc", "--workers", "2"]) == 0
    assert list(done_frames(out)) == list(range(6))
    ref = _arrays(serial)
    for n, a in _arrays(out).items():
        np.testing.assert_array_equal(a, ref[n])


def test_series_bad_input(files, recipe, rec, data, tmp_path, capsys):
    _, _, _, frames = data
    pipeline = Pipeline(recipe, reconstructor=rec)
    with pytest.raises(SsdpcError, match="frame shape .* differs from the calibration"):
        pipeline.run(frames[:2, :-8], ZarrSink(tmp_path / "a.zarr"), progress=False)
    with pytest.raises(SsdpcError, match="--workers must be >= 1"):
        Pipeline(recipe, workers=0)
    with pytest.raises(SsdpcError, match="give the series as a TIFF path"):
        Pipeline(recipe, workers=2).run(frames[:2], ZarrSink(tmp_path / "c.zarr"))
    foreign = tmp_path / "foreign.zarr"
    foreign.mkdir()
    (foreign / "data.txt").write_text("not ours")
    with pytest.raises(SsdpcError, match="not written by `ssdpc reconstruct`"):
        pipeline.run(frames[:1], ZarrSink(foreign), progress=False)
    capsys.readouterr()
    assert main(_args(files, tmp_path / "one.ome.tif") + ["--workers", "2"]) == 2
    err = capsys.readouterr().err
    assert "write it to OME-Zarr" in err and err.count("\n") == 1
    if not gpu_available():
        assert main(_args(files, tmp_path / "gpu.zarr") + ["--device", "gpu"]) == 2
        err = capsys.readouterr().err
        assert "--device gpu" in err and err.count("\n") == 1 and not (tmp_path / "gpu.zarr").exists()
    assert (
        main(
            [
                "reconstruct",
                str(tmp_path / "missing.tif"),
                "--calibration",
                str(files / "cal.json"),
                "-o",
                str(tmp_path / "m.zarr"),
            ]
        )
        == 2
    )
    assert "file not found" in capsys.readouterr().err
    assert not (tmp_path / "m.zarr").exists()


def test_a_store_is_resumed_on_the_other_device(data, recipe, rec, tmp_path):
    """The store promises that a run may be resumed on the other device (CPU and GPU agree to float
    rounding): the device is part of the operators' key, not of what the store holds."""
    from fake_device import fake_gpu

    optics, cal, flat, frames = data
    gpu = Job(run_config(optics, device="gpu", **SETTINGS), cal, flat, stacks=True)
    assert gpu.result_key == recipe.result_key and gpu.key != recipe.key
    out = tmp_path / "resumed.zarr"
    Pipeline(recipe, reconstructor=rec).run(frames[:3], ZarrSink(out), progress=False, stop_after=1)
    on_gpu = (
        gpu.build() if gpu_available() else Reconstructor(gpu.config, cal, flat=flat, stacks=True, backend=fake_gpu())
    )
    report = Pipeline(gpu, reconstructor=on_gpu).run(frames[:3], ZarrSink(out), progress=False)
    assert (report.skipped, report.written) == (1, 2) and list(done_frames(out)) == [0, 1, 2]
    ri = read_ome_zarr(out, "ri")[0]
    np.testing.assert_allclose(ri[2], rec.reconstruct(frames[2]).ri, atol=1e-5)


def test_raw_frames_in_an_ome_zarr_image_stream_like_a_tiff(data, recipe, rec, tmp_path):
    """A camera that records to OME-Zarr: the (t, y, x) image is read one chunk per frame, named by
    its files' content for the resume stamp, and reconstructs to the TIFF's numbers."""
    import zarr

    from napari_ssdpc.io.frame_source import StoredFrames

    _, _, _, frames = data
    raw = tmp_path / "raw.zarr"
    image = zarr.open_group(str(raw / "frames"), mode="w", zarr_format=2)
    axes = [{"name": "t", "type": "time"}, {"name": "y", "type": "space"}, {"name": "x", "type": "space"}]
    image.attrs["multiscales"] = [{"version": "0.4", "axes": axes, "datasets": [{"path": "0"}]}]
    image.create_array("0", shape=frames[:3].shape, chunks=(1, *frames.shape[1:]), dtype=frames.dtype)
    image["0"][:] = frames[:3]
    source = StoredFrames(raw / "frames")
    assert len(source) == 3 and source.frame_shape == frames.shape[1:]
    np.testing.assert_array_equal(source[2], frames[2])
    first = source.identity()
    image["0"][1] = frames[1] + 1
    assert StoredFrames(raw / "frames").identity()["sha256"] != first["sha256"]  # another recording
    image["0"][1] = frames[1]
    report = Pipeline(recipe, reconstructor=rec).run(source, ZarrSink(tmp_path / "out.zarr"), progress=False)
    assert report.written == 3
    np.testing.assert_array_equal(read_ome_zarr(tmp_path / "out.zarr", "ri")[0][0], rec.reconstruct(frames[0]).ri)
    with pytest.raises(SsdpcError, match="not a readable OME-Zarr"):
        StoredFrames(tmp_path)
