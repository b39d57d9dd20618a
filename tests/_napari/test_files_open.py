"""Files open without questions: the plugin's own results and raw frames open in µm with File › Open
(no "Choose reader"), and a JSON that is not the plugin's is never claimed by it."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

from napari.errors import MultipleReaderError
from napari.plugins import _npe2

from napari_ssdpc._napari import reader as _reader
from napari_ssdpc._napari import writer as _writer
from napari_ssdpc._napari.layers import result_layer
from napari_ssdpc._napari.preferences import OWN_PATTERNS, PLUGIN, prefer_own_readers


def _result(name="bead"):
    vol = np.full((5, 40, 48), 1.518, np.float32)
    vol[2, 18:22, 20:26] = 1.50
    data, kw, _ = result_layer(vol, "ri", (2.0, 0.85, 0.85), (-4.0, -17.0, -20.4), name=name, info={})
    return data, kw


def test_the_plugins_own_results_open_in_um_without_choosing_a_reader(make_napari_viewer, tmp_path):
    viewer = make_napari_viewer()
    data, kw = _result()
    tif = tmp_path / "bead.ssdpc.ome.tif"
    store = tmp_path / "bead.ssdpc.zarr"
    _writer.write_volume(str(tif), data, kw)
    _writer.write_volume(str(store), data, kw)
    # napari's builtin reader matches every *.tif and *.zarr: both readers compete ("Choose reader") ...
    assert {PLUGIN, "napari"} <= set(_npe2.get_readers(str(tif)))
    with pytest.raises(MultipleReaderError):
        viewer.open(tif, plugin=None)  # File › Open's call: this error is napari's "Choose reader" dialog
    assert set(prefer_own_readers()) == set(OWN_PATTERNS)  # ... until the plugin is the preferred one
    assert prefer_own_readers() == []  # once: a preference the user changes afterwards is kept
    for path in (tif, store):
        [layer] = viewer.open(path, plugin=None)  # as File › Open: no dialog
        assert layer.name == "bead RI" and [str(u) for u in layer.units] == ["micrometer"] * 3
        assert np.allclose(layer.scale, (2.0, 0.85, 0.85)) and layer.metadata["ssdpc"]["kind"] == "result"
        assert np.array_equal(np.asarray(layer.data), data)
        viewer.layers.clear()


def test_a_user_preference_is_kept(make_napari_viewer):
    from napari.settings import get_settings

    make_napari_viewer()
    plugins = get_settings().plugins
    plugins.extension2reader = {**plugins.extension2reader, "*.lf.tif": "napari"}
    prefer_own_readers()
    assert plugins.extension2reader["*.lf.tif"] == "napari"
    assert plugins.extension2reader["*.ssdpc.zarr/"] == PLUGIN


def test_a_raw_frame_named_lf_opens_with_the_plugin(make_napari_viewer, tmp_path):
    import tifffile

    viewer = make_napari_viewer()
    prefer_own_readers()
    path = tmp_path / "cells.lf.tif"
    tifffile.imwrite(path, np.random.default_rng(0).integers(100, 4000, (96, 128), dtype=np.uint16))
    [layer] = viewer.open(path, plugin=None)  # as File › Open: no dialog
    assert layer.name == "cells.lf" and layer.metadata["ssdpc"]["kind"] == "raw"  # read by this plugin


def test_only_the_plugins_own_json_is_claimed(tmp_path):
    foreign = tmp_path / "data.json"
    foreign.write_text(json.dumps({"a": 1}))
    assert PLUGIN not in _npe2.get_readers(str(foreign))  # napari's own "no reader" message, not ours
    for name in ("calib.json", "calibration.json", "cal.json", "bead_cal.json", "white-calibration.json"):
        assert PLUGIN in _npe2.get_readers(str(tmp_path / name)), name
    other = tmp_path / "calibration.json"
    other.write_text(json.dumps({"format": "something else"}))
    assert _reader.get_calibration_reader(str(other)) is None  # a foreign JSON of such a name: None
