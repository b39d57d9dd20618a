"""The DPC stack widget: opened from the Plugins menu, it refuses to run without a stack or with a
light-field optics file; on the real Siemens star (tests/data/dpc_cmat) its phase layer, in µm, is the
Waller-Lab solver's phase. The reconstruction itself is tested in tests/reconstruction/test_led_dpc.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps

DATA = Path(__file__).parents[1] / "data" / "dpc_cmat"


def test_the_widget_reconstructs_a_stack_layer_into_a_phase_layer_in_micrometres(
    make_napari_viewer, qtbot, monkeypatch, tmp_path
):
    from napari_ssdpc._napari import notify
    from napari_ssdpc._napari.widgets.dpc import DpcDock

    shown = []
    monkeypatch.setattr(notify, "error", lambda m: shown.append(str(m)))
    viewer = make_napari_viewer()
    _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "DPC stack (LED array, segmented condenser)")
    assert isinstance(dock, DpcDock)
    widget = dock.step
    assert widget.stack.value is None
    assert widget.run() is None and "no DPC stack" in shown[-1]
    viewer.add_image(tifffile.imread(DATA / "testDataset_dpc.tif"), name="star")
    assert widget.stack.value.name == "star"
    light_field = tmp_path / "lf.yaml"
    light_field.write_text("objective: {na: 0.4}\nmla: {pitch_um: 500}\n")
    widget.optics.value = light_field
    assert widget.run() is None and "light-field optics file" in shown[-1]
    widget.optics.value = DATA / "optics.yaml"
    widget.run()
    _steps.wait_for(qtbot, widget)
    layer = viewer.layers["star phase"]
    assert np.allclose(layer.scale, [0.1135, 0.1135]) and tuple(str(u) for u in layer.units) == ("micrometer",) * 2
    peer = tifffile.imread(DATA / "peer_phase.tif")
    assert np.corrcoef(np.ravel(layer.data), np.ravel(peer))[0, 1] >= 0.999
    assert widget.status.value.startswith("star: phase") and len(shown) == 2
