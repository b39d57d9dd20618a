"""`ssdpc measure` and ``measure_result``: results written by the product's own sinks (a series
store, an OME-TIFF) are read back, measured and tabled; bad input and foreign files are refused."""

from pathlib import Path

import numpy as np
import pytest
import tifffile
import zarr

from analysis_store import ALPHA, N_MEDIUM, X, Y, Z, result, run_settings, source, truth, write_moving_store
from napari_ssdpc._version import SOFTWARE
from napari_ssdpc.analysis.objects import measure_objects
from napari_ssdpc.analysis.result_files import open_result
from napari_ssdpc.analysis.table import COLUMNS, csv_path, measure_result, read_csv
from napari_ssdpc.cli.main import main
from napari_ssdpc.pipeline.sinks import OmeTiffSink
from napari_ssdpc.simulation import moving, phantoms


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    out = write_moving_store(tmp_path_factory.mktemp("measure") / "cells.zarr")
    return out, moving.moving_sample(20)[:6]


def test_a_series_store_gives_one_track_with_the_truth_s_mass_and_path(store, capsys):
    out, series = store
    assert main(["measure", str(out)]) == 0
    table = csv_path(out)
    assert table == out.parent / "cells_objects.csv" and f"wrote {table}" in capsys.readouterr().out
    assert table.read_text().splitlines()[0] == ",".join(COLUMNS)
    rows = read_csv(table)
    assert [r["t"] for r in rows] == [0, 1, 2, 3, 4]  # frame 5 is not marked done: not measured
    assert {r["track"] for r in rows} == {1}
    for r, p in zip(rows, series):
        mass, centroid = truth(p)
        assert r["dry_mass_pg"] == pytest.approx(mass / ALPHA, rel=0.1)  # the result's α, not 0.19
        assert np.linalg.norm([r["x_um"] - centroid[0], r["y_um"] - centroid[1], r["z_um"] - centroid[2]]) < 1.0
        # the file path changes nothing: the same numbers as the volume measured in memory
        (direct,) = measure_objects(result(p, r["t"]).delta_n, Z, Y, X, n_medium=N_MEDIUM)
        assert r["at_edge"] == 0 and r["volume_um3"] == pytest.approx(direct["volume_um3"], rel=1e-5)
        assert r["peak_ri"] == pytest.approx(direct["peak_ri"], abs=1e-6)
        assert r["mean_ri"] == pytest.approx(N_MEDIUM + r["integrated_dn_um3"] / r["volume_um3"], abs=1e-5)


def test_the_grid_is_read_back_as_written(store):
    stored = open_result(store[0])
    assert stored.frames == [0, 1, 2, 3, 4] and stored.n_medium == N_MEDIUM
    assert stored.refraction_increment_um3_pg == ALPHA
    np.testing.assert_allclose(stored.z_um, Z, atol=1e-6)
    np.testing.assert_allclose(stored.y_um, Y, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(stored.x_um, X, rtol=1e-4, atol=1e-4)
    t, dn = next(iter(stored))
    assert t == 0 and dn.shape == (len(Z), len(Y), len(X))
    np.testing.assert_allclose(dn, result(moving.moving_sample(20)[0], 0).delta_n, atol=1e-6)


def test_an_ome_tiff_frame_and_the_python_api(tmp_path):
    cell = phantoms.cell(center_um=(5.0, -4.0, 2.0))
    _, optics = run_settings()
    out = tmp_path / "cell.ome.tif"
    sink = OmeTiffSink({"ri": out}, {"software": SOFTWARE, "optics": optics})
    sink.open(None, None, source(1))
    sink.write(0, result(cell, 0))
    rows, path = measure_result(out)
    assert path == tmp_path / "cell_objects.csv"
    (r,) = rows
    mass, centroid = truth(cell)
    assert r["t"] == 0 and r["track"] == 1
    assert r["dry_mass_pg"] == pytest.approx(mass / ALPHA, rel=0.1)
    assert r["volume_um3"] == pytest.approx(4 / 3 * np.pi * 12 * 8 * 5, rel=0.1)
    assert np.linalg.norm([r["x_um"] - centroid[0], r["y_um"] - centroid[1], r["z_um"] - centroid[2]]) < 1.0
    back = read_csv(path)
    assert back[0]["dry_mass_pg"] == pytest.approx(r["dry_mass_pg"], rel=1e-5)
    # α given by the user wins over the result's
    rows, _ = measure_result(out, refraction_increment_um3_pg=0.19)
    assert rows[0]["dry_mass_pg"] == pytest.approx(r["dry_mass_pg"] * ALPHA / 0.19, rel=1e-9)


def _one_line(capsys, argv):
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("ssdpc: error")]
    assert len(lines) == 1 and "Traceback" not in err
    return lines[0]


def test_a_foreign_csv_is_never_replaced_and_ours_is(store, tmp_path, capsys):
    out, _ = store
    foreign = tmp_path / "mine.csv"
    foreign.write_text("my,own,notes\n")
    assert "did not write" in _one_line(capsys, ["measure", out, "-o", foreign])
    assert foreign.read_text() == "my,own,notes\n"
    assert main(["measure", str(out), "-o", str(foreign), "--overwrite"]) == 0
    assert len(read_csv(foreign)) == 5
    assert main(["measure", str(out), "-o", str(foreign), "--min-volume", "1e6"]) == 0  # ours: replaced
    assert read_csv(foreign) == []


def test_what_is_not_a_result_is_one_line(tmp_path, capsys):
    raw = tmp_path / "raw.tif"
    tifffile.imwrite(raw, np.zeros((8, 8), np.uint16))
    assert "not a result of napari-ssdpc" in _one_line(capsys, ["measure", raw])
    (tmp_path / "empty.zarr").mkdir()
    assert "is not an OME-Zarr store" in _one_line(capsys, ["measure", tmp_path / "empty.zarr"])
    zarr.open_group(str(tmp_path / "other.zarr"), mode="w").create_group("ri")
    assert "holds no RI volume" in _one_line(capsys, ["measure", tmp_path / "other.zarr"])
    assert "file not found" in _one_line(capsys, ["measure", tmp_path / "none.zarr"])
    (tmp_path / "notes.txt").write_text("x")
    assert "neither an OME-TIFF nor an OME-Zarr" in _one_line(capsys, ["measure", tmp_path / "notes.txt"])
    assert not list(tmp_path.glob("*.csv"))


def test_a_phase_file_and_bad_options_are_one_line(tmp_path, store, capsys):
    cell = phantoms.cell()
    _, optics = run_settings()
    sink = OmeTiffSink({"ri": tmp_path / "c.ome.tif", "phase": tmp_path / "c_phase.ome.tif"}, {"optics": optics})
    sink.open(None, None, source(1))
    sink.write(0, result(cell, 0))
    assert "not RI or Δn" in _one_line(capsys, ["measure", tmp_path / "c_phase.ome.tif"])
    assert "k_low" in _one_line(capsys, ["measure", store[0], "--k", "2", "--k-low", "3"])
    assert "max step" in _one_line(capsys, ["measure", store[0], "--max-step", "0"])
    assert "fraction" in _one_line(capsys, ["measure", store[0], "--fraction", "0.1", "--fraction-low", "0.3"])


def test_what_ssdpc_reconstruct_writes_is_measured(synthetic_series, tmp_path, capsys):
    """The OME-TIFF and the store of `ssdpc reconstruct` itself (frames of the synthetic series)."""
    _, cal, flat, frames, _ = synthetic_series
    tifffile.imwrite(tmp_path / "raw.tif", frames[:2])
    tifffile.imwrite(tmp_path / "one.tif", frames[0])
    tifffile.imwrite(tmp_path / "flat.tif", flat)
    cal.to_json(tmp_path / "cal.json")
    common = ["--calibration", tmp_path / "cal.json", "--flat", tmp_path / "flat.tif", "--z", "-4", "4", "--dz", "4"]
    grids = []
    for raw, out, save in (("one.tif", "one.ome.tif", []), ("raw.tif", "series.zarr", ["--save", "delta_n"])):
        argv = ["reconstruct", tmp_path / raw, *common, "--method", "wotf", *save, "-o", tmp_path / out]
        assert main([str(a) for a in argv]) == 0, capsys.readouterr().err
        stored = open_result(tmp_path / out)
        assert stored.n_medium == cal.optics.medium_index and len(stored.z_um) == 3
        np.testing.assert_allclose(np.diff(stored.z_um), 4.0)
        grids.append((stored.y_um, stored.x_um))
        assert main(["measure", str(tmp_path / out)]) == 0, capsys.readouterr().err
        table = csv_path(tmp_path / out)
        assert table.read_text().splitlines()[0] == ",".join(COLUMNS)
        assert {r["t"] for r in read_csv(table)} <= ({0} if out.endswith(".tif") else {0, 1})
    # a store with Δn saved is read from it: the same as its RI less the medium
    ri = zarr.open_group(str(tmp_path / "series.zarr"), mode="r")["ri"]["0"][1]
    np.testing.assert_allclose(stored.delta_n(1), ri - np.float32(stored.n_medium), atol=1e-6)
    # the OME-TIFF's lateral grid (centred on the axis) is the store's (its NGFF translation)
    for a, b in zip(*grids):
        np.testing.assert_allclose(a, b, atol=1e-4)


def _damage(store, how):
    root = zarr.open_group(str(store), mode="r+")
    g = root["ri"]
    attrs = dict(g.attrs)
    ms = attrs["multiscales"][0]
    scale = ms["datasets"][0]["coordinateTransformations"][0]
    if how in ("voxel-inf", "ri-plus-5"):  # values no sample has: one infinite voxel, every RI + 5
        a = g["0"]
        if how == "voxel-inf":
            a[0, 0, 0, 0] = np.inf
        else:
            a[0] = a[0] + 5.0
        return
    if how == "chunk":  # a frame's chunk overwritten with junk
        (next(p for p in (store / "ri" / "0").rglob("*") if p.is_file() and not p.name.startswith("."))).write_bytes(
            b"junk"
        )
        return
    damage = {
        "scale-nan": lambda: scale.update(scale=[1.0, float("nan"), 1.0, 1.0]),
        "scale-zero": lambda: scale.update(scale=[1.0, 0.0, 1.0, 1.0]),
        "scale-text": lambda: scale.update(scale="abc"),
        "no-axes": lambda: ms.pop("axes"),
        "dataset-missing": lambda: ms["datasets"][0].update(path="nope"),
        "transforms-missing": lambda: ms["datasets"][0].pop("coordinateTransformations"),
        "no-medium": lambda: attrs.update(napari_ssdpc={**attrs["napari_ssdpc"], "optics": {}}),
        "medium-text": lambda: attrs.update(napari_ssdpc={**attrs["napari_ssdpc"], "optics": {"medium_index": "x"}}),
        "alpha-negative": lambda: attrs.update(
            napari_ssdpc={**attrs["napari_ssdpc"], "settings": {"refraction_increment_um3_pg": -1}}
        ),
    }
    damage[how]()
    attrs["multiscales"] = [ms]
    g.attrs.clear()
    g.attrs.update(attrs)


@pytest.mark.parametrize(
    "how",
    [
        "scale-nan",
        "scale-zero",
        "scale-text",
        "no-axes",
        "dataset-missing",
        "transforms-missing",
        "no-medium",
        "medium-text",
        "alpha-negative",
        "chunk",
        "voxel-inf",
        "ri-plus-5",
    ],
)
def test_a_damaged_store_is_one_line_and_writes_nothing(store, tmp_path, capsys, how):
    import shutil

    damaged = tmp_path / "d.zarr"
    shutil.copytree(store[0], damaged)
    _damage(damaged, how)
    line = _one_line(capsys, ["measure", damaged])
    assert str(damaged) in line or "refraction increment" in line
    assert {"voxel-inf": "not finite", "ri-plus-5": "outside any sample's"}.get(how, "") in line
    assert not csv_path(damaged).exists()


def test_impossible_claims_and_outputs_are_one_line_not_a_hang(store, tmp_path, capsys):
    """Done flags claiming 10^9 frames are read from the flags written (not 10^9 absent chunks); a
    device as the CSV (/dev/full, which never ends when read) is refused, never read or replaced."""
    import shutil

    from napari_ssdpc.io.store import DONE

    claimed = tmp_path / "claimed.zarr"
    shutil.copytree(store[0], claimed)
    zarr.open_group(str(claimed), mode="r+")[DONE].resize((10**9,))
    assert main(["measure", str(claimed), "-o", str(tmp_path / "claimed.csv")]) == 0
    assert main(["measure", str(store[0]), "-o", str(tmp_path / "as-written.csv")]) == 0
    rows = read_csv(tmp_path / "claimed.csv")
    assert len({r["t"] for r in rows}) == 5 and rows == read_csv(tmp_path / "as-written.csv")
    if Path("/dev/full").exists():
        assert "not a regular file" in _one_line(capsys, ["measure", store[0], "-o", "/dev/full"])
        assert Path("/dev/full").is_char_device()
