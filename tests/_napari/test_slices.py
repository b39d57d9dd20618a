"""xz and yz sections of a reconstruction beside napari's xy view."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

from napari_ssdpc._napari.layers import result_layer
from napari_ssdpc._napari.widgets.slices import SlicesWidget, sections


def _volume():
    """A (z, y, x) RI volume, 2 x 0.85 x 0.85 µm voxels, with a low-index bead centred at
    (z, y, x) = (4, -3.4, 5.1) µm."""
    z0, y0, x0 = -16.0, -13.6, -13.6
    z, y, x = np.meshgrid(z0 + 2.0 * np.arange(17), y0 + 0.85 * np.arange(33), x0 + 0.85 * np.arange(33), indexing="ij")
    v = 1.518 - 0.03 * (((x - 5.1) ** 2 + (y + 3.4) ** 2 + ((z - 4.0) / 2) ** 2) < 16)
    return result_layer(
        v.astype(np.float32), "ri", (2.0, 0.85, 0.85), (z0, y0, x0), name="bead", info={"medium_index": 1.518}
    )


def test_sections_pass_through_the_point_in_micrometres(make_napari_viewer):
    viewer = make_napari_viewer()
    data, kwargs, _ = _volume()
    layer = viewer.add_image(data, **kwargs)
    s = sections(layer, (4.0, -3.4, 5.1))
    assert s["at"] == (10, 12, 22)  # z = -16 + 2·10, y = -13.6 + 0.85·12, x = -13.6 + 0.85·22
    np.testing.assert_array_equal(s["xz"], data[:, 12, :])
    np.testing.assert_array_equal(s["yz"], data[:, :, 22])
    assert s["extent_xz"] == pytest.approx((-14.025, 14.025, 17.0, -17.0))  # voxel edges, µm; z down
    zi, xi = np.nonzero(s["xz"] < 1.5)  # the bead's section: centred on it
    assert abs(-16 + 2 * zi.mean() - 4.0) < 0.5 and abs(-13.6 + 0.85 * xi.mean() - 5.1) < 0.5


def test_the_slices_widget_follows_the_viewer(make_napari_viewer):
    viewer = make_napari_viewer()
    w = SlicesWidget(viewer)
    w.update()
    assert "reconstruct a frame" in w.info.value
    data, kwargs, _ = _volume()
    viewer.add_image(data, **kwargs)
    w.controls.reset_choices()
    assert w.layer.value is viewer.layers["bead RI"]
    viewer.dims.set_point(0, 4.0)
    w.update()
    assert w.info.value.startswith("through z 4.0 µm") and len(w.figure.axes) == 2
    assert [ax.get_ylabel() for ax in w.figure.axes] == ["z (µm)", "z (µm)"]
