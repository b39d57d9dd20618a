"""Objects over time in napari: a result layer measured as the CLI measures it, the tracks layer in
µm, the objects table read back as tracks, and the dock (skipped without a display)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("napari")

from napari_ssdpc._napari.reader import read_result
from napari_ssdpc._napari.tracks import get_objects_reader, measure_layer, tracks_layer
from napari_ssdpc.analysis.table import COLUMNS, measure_result, read_csv


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """The 6-frame moving-sample store of tests/analysis/test_measure.py (frames 0-4 complete)."""
    from analysis_store import write_moving_store

    return write_moving_store(tmp_path_factory.mktemp("objects") / "cells.zarr")


def _ri_layer(store):
    (layer,) = [lyr for lyr in read_result(store) if lyr[1]["metadata"]["ssdpc"]["quantity"] == "ri"]
    return layer


def test_a_result_layer_is_measured_as_the_file_is(store):
    data, kwargs, _ = _ri_layer(store)
    info = kwargs["metadata"]["ssdpc"]
    rows = measure_layer(data, kwargs["scale"], kwargs["translate"], info)
    expected, _ = measure_result(store, store.parent / "api_objects.csv")
    assert [r["t"] for r in rows] == [0, 1, 2, 3, 4]  # the NaN frame 5 (not written) is skipped
    for a, b in zip(rows, expected):
        for c in ("track", "x_um", "y_um", "z_um", "volume_um3", "dry_mass_pg", "mean_ri", "peak_ri"):
            assert a[c] == pytest.approx(b[c], rel=1e-4, abs=1e-4), c


def test_tracks_are_in_micrometres_with_every_column_as_a_feature(store):
    rows, path = measure_result(store, store.parent / "t_objects.csv")
    data, kwargs, kind = tracks_layer(rows)
    assert kind == "tracks" and data.shape == (5, 5)
    np.testing.assert_allclose(data[:, 0], 1)
    np.testing.assert_allclose(data[:, 1], [0, 1, 2, 3, 4])
    np.testing.assert_allclose(data[:, 2:], [[r["z_um"], r["y_um"], r["x_um"]] for r in rows])
    assert set(kwargs["features"]) == set(COLUMNS) and kwargs["units"][1:] == ("µm",) * 3
    reader = get_objects_reader(str(path))
    assert reader is not None
    ((back, kw, _),) = reader(str(path))
    np.testing.assert_allclose(back, data, rtol=1e-5)
    foreign = store.parent / "other_objects.csv"
    foreign.write_text("a,b\n1,2\n")
    assert get_objects_reader(str(foreign)) is None


def test_the_dock_measures_shows_and_saves(make_napari_viewer, qtbot, store, tmp_path):
    from napari_ssdpc._napari.objects_dock import ObjectsDock

    viewer = make_napari_viewer()
    data, kwargs, _ = _ri_layer(store)
    viewer.add_image(data, **kwargs)
    dock = ObjectsDock(viewer)
    viewer.window.add_dock_widget(dock, name="objects")
    assert dock.layer.value is not None
    worker = dock.measure()
    assert worker is not None
    qtbot.waitUntil(lambda: dock.rows is not None, timeout=60000)
    assert len(dock.rows) == 5 and dock.table.rowCount() == 5
    tracks = viewer.layers[f"{dock.layer.value.name} objects"]
    assert tracks.data.shape == (5, 5)
    assert len(dock.figure.axes) == 2 and len(dock.figure.axes[0].lines) == 1
    dock.path.value = tmp_path / "shown_objects.csv"
    assert dock.save_table() == tmp_path / "shown_objects.csv"
    assert len(read_csv(tmp_path / "shown_objects.csv")) == 5


def test_the_dock_opens_from_the_plugins_menu(make_napari_viewer, monkeypatch):
    from napari_ssdpc._napari import notify
    from napari_ssdpc._napari.objects_dock import ObjectsDock

    shown = []
    monkeypatch.setattr(notify, "error", lambda m: shown.append(str(m)))
    viewer = make_napari_viewer()
    _, widget = viewer.window.add_plugin_dock_widget("napari-ssdpc", "Objects over time")
    assert isinstance(widget, ObjectsDock) and widget.layer.value is None
    assert widget.measure() is None  # no result layer: refused with a message, nothing runs
    assert widget.save_table() is None
    assert shown == ["open or reconstruct a result first: no RI layer to measure", "measure the objects first"]
