"""napari readers, writer and sample data (no viewer needed)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile

from napari_ssdpc._napari import reader as _reader
from napari_ssdpc._napari import sample_cache as _sample_cache
from napari_ssdpc._napari import sample_data as _sample_data
from napari_ssdpc._napari import writer as _writer
from napari_ssdpc.calibration import calibrate
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.frames import write_ome_tiff
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.sample_free import white_frame

pytest.importorskip("napari")


def _layers(path, get_reader):
    reader = get_reader(str(path))
    assert reader is not None, f"{get_reader.__name__} refused {path}"
    return reader(str(path))


# ------------------------------------------------------------------------ raw frames
def test_raw_frame_reader(tmp_path):
    frame = np.random.default_rng(0).integers(100, 4000, (96, 128), dtype=np.uint16)
    p = tmp_path / "frame.tif"
    tifffile.imwrite(p, frame)
    [(data, kw, kind)] = _layers(p, _reader.get_raw_reader)
    assert kind == "image" and data.shape == (96, 128) and "axis_labels" not in kw
    assert np.array_equal(np.asarray(data), frame)
    assert kw["metadata"]["ssdpc"]["kind"] == "raw" and kw["name"] == "frame"
    # a plain multi-page TIFF (one page per frame, no metadata) is a (t, y, x) series
    pages = tmp_path / "pages.tif"
    for k in range(4):
        tifffile.imwrite(pages, frame + k, append=True, metadata=None)
    [(data, kw, _)] = _layers(pages, _reader.get_raw_reader)
    assert data.shape == (4, 96, 128) and kw["axis_labels"] == ("t", "y", "x")
    assert np.array_equal(np.asarray(data[3]), frame + 3)


@pytest.mark.parametrize("compression", [None, "zlib"])
def test_raw_series_reader_is_lazy(tmp_path, compression):
    series = np.random.default_rng(1).integers(0, 4095, (3, 64, 80), dtype=np.uint16)
    p = tmp_path / "series.ome.tif"
    tifffile.imwrite(p, series, photometric="minisblack", metadata={"axes": "TYX"}, compression=compression, ome=True)
    [(data, kw, _)] = _layers(p, _reader.get_raw_reader)
    assert data.shape == (3, 64, 80) and kw["axis_labels"] == ("t", "y", "x")
    if compression is None:
        assert isinstance(data, np.memmap)  # pixels stay on disk until sliced
    else:
        import dask.array as da

        assert isinstance(data, da.Array)  # compressed: lazily through tifffile's zarr store
    assert np.array_equal(np.asarray(data[2]), series[2])


def test_foreign_files_give_none(tmp_path):
    rgb = tmp_path / "photo.tif"
    tifffile.imwrite(rgb, np.zeros((64, 64, 3), np.uint8), photometric="rgb")
    vol = tmp_path / "stack.ome.tif"
    tifffile.imwrite(
        vol,
        np.zeros((5, 64, 64), np.float32),
        ome=True,
        metadata={"axes": "ZYX", "PhysicalSizeZ": 1.0, "PhysicalSizeX": 0.2, "PhysicalSizeY": 0.2},
    )
    text = tmp_path / "notes.tif"
    text.write_text("not a tiff")
    other_json = tmp_path / "other.json"
    other_json.write_text(json.dumps({"format": "something-else"}))
    for p in (rgb, vol, text, tmp_path / "missing.tif"):
        assert _reader.get_raw_reader(str(p)) is None, p.name
        assert _reader.get_result_reader(str(p)) is None, p.name
    assert _reader.get_calibration_reader(str(other_json)) is None
    assert _reader.get_calibration_reader(str(text)) is None
    assert _reader.get_raw_reader([str(rgb), str(vol)]) is None
    # our own reconstruction is not a raw frame
    ours = tmp_path / "ri.ome.tif"
    _writer.write_result(ours, np.zeros((4, 40, 40), np.float32), voxel_um=(2, 0.8, 0.8), info={"quantity": "ri"})
    assert _reader.get_raw_reader(str(ours)) is None and _reader.get_result_reader(str(ours)) is not None
    # an OME-TIFF volume from elsewhere (no napari-ssdpc description) is not a result
    plain = tmp_path / "plain.ome.tif"
    write_ome_tiff(plain, np.zeros((4, 40, 40), np.float32), axes="ZYX", voxel_um=(1, 1, 1))
    assert _reader.get_result_reader(str(plain)) is None


def test_bad_files_give_none_never_an_exception(tmp_path):
    nested = tmp_path / "nested.json"
    nested.write_text("[" * 100_000 + "]" * 100_000)  # RecursionError in the JSON parser
    assert _reader.get_calibration_reader(str(nested)) is None
    latin = tmp_path / "latin.json"
    latin.write_bytes(b'{"format": "caf\xe9"}')
    assert _reader.get_calibration_reader(str(latin)) is None
    frame = np.random.default_rng(4).integers(0, 4095, (128, 160), dtype=np.uint16)
    whole = tmp_path / "whole.tif"
    tifffile.imwrite(whole, frame)
    cut = tmp_path / "cut.tif"  # an interrupted copy: the second half of the pixels is missing
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    assert _reader.get_raw_reader(str(whole)) is not None
    assert _reader.get_raw_reader(str(cut)) is None and _reader.get_result_reader(str(cut)) is None


def test_opens_the_demo_volume_and_a_single_plane(tmp_path):
    """The demo's ri.ome.tif (written by ``write_ome_tiff``, as the demo does) and a single-plane
    result (``--z 5 5``) open as (z, y, x) volumes with dz as the z voxel size."""
    for nz in (21, 1):
        p = tmp_path / f"ri{nz}.ome.tif"
        vol = np.full((nz, 40, 48), 1.5, np.float32)
        desc = {"quantity": "refractive index", "settings": {"z_min_um": 5.0}, "optics": {"medium_index": 1.518}}
        write_ome_tiff(p, vol, axes="ZYX", voxel_um=(0.5, 0.85, 0.85), description=desc)
        assert _reader.get_raw_reader(str(p)) is None
        [(data, kw, _)] = _layers(p, _reader.get_result_reader)
        assert data.shape == (nz, 40, 48) and kw["scale"] == (0.5, 0.85, 0.85) and kw["translate"][0] == 5.0
        assert kw["metadata"]["ssdpc"]["quantity"] == "ri" and np.array_equal(np.asarray(data), vol)


# ----------------------------------------------------------------------- calibration
def test_calibration_reader_circles_and_labelled_centres(tmp_path):
    optics = Optics.paper()
    cal = calibrate(white_frame(optics, rng=np.random.default_rng(5)), optics)
    p = cal.to_json(tmp_path / "calib.json")
    (circles, skw, sk), (pts, pkw, pk), (arrows, vkw, vk) = _layers(p, _reader.get_calibration_reader)
    k = len(cal.lenslets)
    assert (sk, pk) == ("points", "points") and skw["metadata"]["ssdpc"]["role"] == "EI circles"
    assert np.allclose(circles[:, ::-1], cal.centres_px, atol=1e-9)  # (y, x) centres
    assert skw["size"] == 2 * cal.ei_radius_px and skw["face_color"] == "transparent"
    assert pts.shape == (k + 1, 2) and np.allclose(pts[:k, ::-1], cal.centres_px)
    assert np.allclose(pts[k, ::-1], cal.grid.axis_px)
    ln = cal.lenslets[3]
    assert pkw["features"]["label"][3] == f"({ln.row}, {ln.col})" and pkw["features"]["label"][k] == "axis"
    assert skw["metadata"]["ssdpc"]["calibration"] == json.loads(p.read_text())
    # each measured centre's deviation from the lattice, as a magnified arrow from its lattice site
    gain = vkw["metadata"]["ssdpc"]["deviation_gain"]
    ok = np.isfinite(cal.deviation_px).all(axis=1)
    assert vk == "vectors" and arrows.shape == (ok.sum(), 2, 2) and gain >= 1
    assert np.allclose((arrows[:, 0] + arrows[:, 1] / gain)[:, ::-1], cal.centres_px[ok], atol=1e-9)
    assert np.isclose(np.hypot(*arrows[:, 1].T).max(), cal.ei_radius_px / 3) or gain in (1.0, 500.0)


# ------------------------------------------------------------------ results: writer
def test_ome_tiff_roundtrip_keeps_scale_and_labels(tmp_path):
    vol = np.random.default_rng(2).normal(1.518, 0.01, (5, 30, 40)).astype(np.float32)
    meta = {
        "name": "bead RI",
        "scale": (2.0, 0.8456, 0.8456),
        "translate": (-4.0, -12.0, -16.0),
        "metadata": {
            "ssdpc": {"kind": "result", "quantity": "ri", "medium_index": 1.518, "settings": {"rl_iterations": 3}}
        },
    }
    [out] = _writer.write_volume(str(tmp_path / "bead.ome.tif"), vol, meta)
    [(data, kw, _)] = _layers(out, _reader.get_result_reader)
    assert np.array_equal(np.asarray(data), vol)
    assert kw["scale"] == (2.0, 0.8456, 0.8456) and kw["translate"] == (-4.0, -12.0, -16.0)
    assert kw["axis_labels"] == ("z", "y", "x") and kw["units"] == ("µm", "µm", "µm") and kw["name"] == "bead RI"
    info = kw["metadata"]["ssdpc"]
    assert info["quantity"] == "ri" and info["settings"] == {"rl_iterations": 3}
    lo, hi = kw["contrast_limits"]
    assert lo < 1.518 < hi and hi - 1.518 == pytest.approx(1.518 - lo)  # centred on the medium
    with tifffile.TiffFile(out) as tif:  # standard OME sizes too
        px = tifffile.xml2dict(tif.ome_metadata)["OME"]["Image"]["Pixels"]
        assert (px["PhysicalSizeZ"], px["PhysicalSizeX"]) == (2.0, 0.8456)


def test_ome_zarr_time_series_roundtrip(tmp_path):
    import dask.array as da
    import zarr

    series = np.random.default_rng(3).normal(0, 1, (3, 4, 20, 24)).astype(np.float32)
    meta = {
        "name": "cells phase",
        "scale": (1.0, 2.0, 0.85, 0.85),
        "translate": (0.0, -4.0, -8.0, -10.0),
        "metadata": {"ssdpc": {"quantity": "phase"}},
    }
    path = tmp_path / "cells.zarr"
    _writer.write_volume(str(path), series, meta)
    _writer.write_volume(str(path), series * 2, meta)  # overwrite: the group is replaced whole
    ri_meta = {**meta, "name": "cells RI", "metadata": {"ssdpc": {"quantity": "ri", "medium_index": 1.33}}}
    _writer.write_volume(str(path), series + 1.33, ri_meta)  # a second quantity in the same store
    g = zarr.open_group(str(path / "phase"), mode="r")
    ms = g.attrs["multiscales"][0]
    assert [a["name"] for a in ms["axes"]] == ["t", "z", "y", "x"] and ms["axes"][1]["unit"] == "micrometer"
    assert ms["datasets"][0]["coordinateTransformations"][0]["scale"] == [1.0, 2.0, 0.85, 0.85]
    layers = _layers(path, _reader.get_result_reader)
    (data, kw, _), (ri, rkw, _) = sorted(layers, key=lambda t: t[1]["name"], reverse=True)
    assert isinstance(data, da.Array) and data.shape == (3, 4, 20, 24)
    assert np.array_equal(np.asarray(data), series * 2) and np.array_equal(np.asarray(ri), series + 1.33)
    assert kw["name"] == "cells phase" and rkw["name"] == "cells RI"
    assert kw["axis_labels"] == ("t", "z", "y", "x") and kw["scale"] == (1.0, 2.0, 0.85, 0.85)
    assert kw["translate"] == (0.0, -4.0, -8.0, -10.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cells.zarr"]  # no temporary folders left
    with pytest.raises(SsdpcError, match="dimensions"):
        _writer.write_volume(str(tmp_path / "x.ome.tif"), np.zeros((10, 10)), {"name": "raw"})


# ----------------------------------------------------------------------- sample data
def test_time_series_sample_is_lazy_20_frames(tmp_path, monkeypatch):
    import dask.array as da

    calls = []
    monkeypatch.setattr(_sample_data, "series_frame", lambda i, n: calls.append(i) or np.zeros((1024, 1024), np.uint16))
    layers = _sample_data.moving_sample_series(prefetch=False)
    series = layers[-1][0]
    assert isinstance(series, da.Array) and series.shape == (20, 1024, 1024) and series.dtype == np.uint16
    assert calls == []  # nothing simulated until a frame is read
    series[7].compute()
    assert calls == [7]
    assert layers[-1][1]["axis_labels"] == ("t", "y", "x")
    assert layers[-1][1]["metadata"]["ssdpc"]["optics"]["medium_index"] == 1.33


def test_time_series_sample_is_made_in_the_background_once_each(monkeypatch):
    """Opening the series starts a thread that makes every frame once, onward from the frame read."""
    import threading
    import time

    made, guard = [], threading.Lock()

    def fake(i, n):
        time.sleep(0.01)
        with guard:
            made.append(i)
        return np.zeros((4, 4), np.uint16)

    monkeypatch.setattr(_sample_data, "series_frame", fake)
    ahead = _sample_data.SeriesPrefetch(6)
    ahead.asked(3)  # the user looks at frame 3 at once
    ahead.thread.join(10)
    assert not ahead.thread.is_alive()
    assert sorted(made) == list(range(6)) and ahead.made == set(range(6))


def test_a_cached_frame_is_made_once_when_two_threads_ask(tmp_path, monkeypatch):
    import threading
    import time

    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path))
    calls = []

    def make():
        calls.append(1)
        time.sleep(0.2)
        return np.full((3, 5), 7, np.uint16)

    out = []
    threads = [threading.Thread(target=lambda: out.append(_sample_cache.cached("f", make, "k"))) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(calls) == 1 and len(out) == 3
    assert all(np.array_equal(o, np.full((3, 5), 7)) for o in out)


# ------------------------------------------------- outputs of `ssdpc reconstruct`
def test_reads_the_cli_reconstruction_outputs(tmp_path):
    """The result reader opens what `ssdpc reconstruct` writes, with µm scale and the view
    centred on the optical axis; a series goes to OME-Zarr and opens as (t, z, y, x)."""
    from napari_ssdpc.cli.main import main

    frame, flat, white, optics = _sample_data.bead_frames()
    tifffile.imwrite(tmp_path / "bead.tif", frame)
    tifffile.imwrite(tmp_path / "flat.tif", flat)
    tifffile.imwrite(
        tmp_path / "series.tif", np.stack([frame, frame]), photometric="minisblack", metadata={"axes": "TYX"}
    )
    calibrate(white, optics).to_json(tmp_path / "calib.json")
    common = [
        "--calibration",
        str(tmp_path / "calib.json"),
        "--flat",
        str(tmp_path / "flat.tif"),
        "--z",
        "-10",
        "10",
        "--dz",
        "2",
        "--iterations",
        "2",
    ]
    assert (
        main(
            [
                "reconstruct",
                str(tmp_path / "bead.tif"),
                *common,
                "--save",
                "phase,dpc",
                "-o",
                str(tmp_path / "out.ome.tif"),
            ]
        )
        == 0
    )
    [(ri, kw, _)] = _layers(tmp_path / "out.ome.tif", _reader.get_result_reader)
    assert kw["name"] == "out RI" and ri.shape == (11, 145, 145)
    assert np.allclose(kw["scale"], (2.0, optics.object_pixel_um, optics.object_pixel_um), rtol=2e-3)
    assert kw["translate"][0] == -10.0 and kw["translate"][1] == pytest.approx(-72 * kw["scale"][1])
    lo, hi = kw["contrast_limits"]
    assert lo < optics.medium_index < hi
    [(_, pkw, _)] = _layers(tmp_path / "out_phase.ome.tif", _reader.get_result_reader)
    assert pkw["name"] == "out phase" and pkw["metadata"]["ssdpc"]["quantity"] == "phase"
    dpc = _layers(tmp_path / "out_dpc.ome.tif", _reader.get_result_reader)
    assert [k["name"] for _, k, _ in dpc] == ["out DPC up-down", "out DPC left-right"]
    assert _reader.get_raw_reader(str(tmp_path / "out.ome.tif")) is None

    series = ["reconstruct", str(tmp_path / "series.tif"), *common, "--no-warm-start", "-o", str(tmp_path / "s.zarr")]
    assert main(series) == 0  # every frame solved alone: frame 1 is the single frame's result
    [(data, skw, _)] = _layers(tmp_path / "s.zarr", _reader.get_result_reader)
    assert data.shape == (2, 11, 145, 145) and skw["axis_labels"] == ("t", "z", "y", "x")
    assert np.array_equal(np.asarray(data[1]), np.asarray(ri))


def test_cache_drops_unfinished_files_left_by_an_exit(tmp_path, monkeypatch):
    import os

    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path))
    folder = _sample_cache.cache_dir()
    old, fresh = folder / ".moving_20_004-x.tif.1.a.part", folder / ".moving_20_005-x.tif.1.b.part"
    old.write_bytes(b"half")
    fresh.write_bytes(b"being written")
    os.utime(old, (1e9, 1e9))
    _sample_cache.cache_dir()
    assert not old.exists() and fresh.exists()
