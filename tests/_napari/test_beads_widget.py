"""The Beads widget: opened from the Plugins menu, it refuses to run without a frame; its beads
become a points layer in µm (one point per bead, its diameter as the size, flagged beads red) and a
table (skipped without a display). The fit itself is tested in tests/reconstruction/test_beads.py."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("napari")

from napari_ssdpc.reconstruction.bead import Bead


def _beads():
    good = Bead((1.0, -2.0, 3.5), 5.0, 1.4646, 0.1316, 3.0, 5.6, True, True)
    flagged = Bead((4.0, 6.0, -8.0), 4.3, 1.40, 0.067, 26.5, 4.3, True, False, "the model leaves 26.5 x the noise")
    return [good, flagged]


def test_the_widget_opens_from_the_plugins_menu_and_needs_a_frame(make_napari_viewer, monkeypatch):
    from napari_ssdpc._napari import notify
    from napari_ssdpc._napari.widgets.beads import BeadsWidget

    shown = []
    monkeypatch.setattr(notify, "error", lambda m: shown.append(str(m)))
    viewer = make_napari_viewer()
    _, widget = viewer.window.add_plugin_dock_widget("napari-ssdpc", "Beads (each fitted as a sphere)")
    assert isinstance(widget, BeadsWidget) and widget.raw.value is None
    assert widget.run() is None
    assert shown and "no raw frame" in shown[0]


def test_fitted_beads_are_points_in_micrometres_and_a_table(make_napari_viewer):
    from napari_ssdpc._napari.widgets.beads import BeadsWidget

    viewer = make_napari_viewer()
    widget = BeadsWidget(viewer)
    text = widget._done(None, "frame", object(), _beads())
    points = viewer.layers["frame beads"]
    assert np.allclose(points.data, [[3.5, -2.0, 1.0], [-8.0, 6.0, 4.0]])  # (z, y, x) µm
    assert np.allclose(points.scale, 1.0) and tuple(str(u) for u in points.units) == ("micrometer",) * 3
    assert list(points.features["RI"]) == [1.4646, 1.4]
    assert np.allclose(points.size, [5.0, 4.3])
    assert np.allclose(points.border_color[1][:3], [1, 0, 0]) and np.allclose(points.border_color[0][:3], [1, 1, 0])
    table = widget.table.to_dict("list")
    assert table["diameter (µm)"] == [5.0, 4.3] and table["check"][0] == "ok"
    assert text == "frame: 2 bead(s), 1 to check (red)"
