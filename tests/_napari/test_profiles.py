"""Line-profile dock: sampled values equal direct interpolation of the layer data."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from scipy import ndimage

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

from napari_ssdpc._napari.profiles import ProfileWidget, orientation, sample_line

SCALE = (2.0, 0.8456, 0.8456)  # (dz, dy, dx) µm, as a reconstruction
ORIGIN = (-20.0, -61.0, -61.0)


def _volume(shape=(21, 145, 145), seed=0):
    rng = np.random.default_rng(seed)
    return (1.518 + 0.01 * ndimage.gaussian_filter(rng.normal(size=shape), 2)).astype(np.float32)


def _expected(data, start_um, end_um, distance_um):
    """map_coordinates (order 1) of the data at the voxel positions along the µm line."""
    a = (np.asarray(start_um) - ORIGIN) / SCALE
    b = (np.asarray(end_um) - ORIGIN) / SCALE
    s = distance_um / np.linalg.norm(np.subtract(end_um, start_um))
    coords = a[:, None] + (b - a)[:, None] * s[None, :]
    return ndimage.map_coordinates(data, coords, order=1)


def _dock(viewer, data):
    img = viewer.add_image(data, scale=SCALE, translate=ORIGIN, name="bead RI", axis_labels=("z", "y", "x"))
    dock = ProfileWidget(viewer)
    viewer.window.add_dock_widget(dock, name="profile")
    dock.image.value = img
    return img, dock


def test_xy_and_xz_profiles_equal_map_coordinates(make_napari_viewer, tmp_path):
    viewer = make_napari_viewer()
    data = _volume()
    img, dock = _dock(viewer, data)
    lines = dock.new_line_layer()
    assert lines.ndim == 3 and np.allclose(lines.scale, SCALE)
    # an xy line in the plane z = -4 µm, and an xz line (axial) through y = 3.4 µm; line vertices are
    # given in the lines layer's data coordinates, i.e. voxels of the image
    xy = (np.array([-4.0, -30.0, -50.0]), np.array([-4.0, 25.0, 40.0]))
    xz = (np.array([-18.0, 3.4, -10.0]), np.array([16.0, 3.4, 22.0]))
    for a, b in (xy, xz):
        lines.add_lines(np.stack([(a - ORIGIN) / SCALE, (b - ORIGIN) / SCALE]))
    # the line as the layer stores it (napari keeps vertices in float32): end points in µm
    xy, xz = ([v.astype(float) * SCALE + ORIGIN for v in lines.data[i]] for i in (0, 1))
    profiles = dock.profiles
    assert [p["orientation"] for p in profiles] == ["xy", "xz"]
    for p, (a, b) in zip(profiles, (xy, xz)):
        d = p["distance_um"]
        assert d[0] == 0 and d[-1] == pytest.approx(np.linalg.norm(b - a), rel=1e-9)
        assert len(d) >= np.linalg.norm((b - a) / SCALE)  # at least one sample per voxel
        np.testing.assert_allclose(p["values"], _expected(data, a, b, d), rtol=0, atol=1e-6)
        np.testing.assert_allclose(p["world"][-1], b, atol=1e-9)
    # the plot follows the line when it moves
    before = profiles[1]["values"].copy()
    shifted = lines.data[1] + np.array([0.0, 5.0, 0.0])
    lines.data = [lines.data[0], shifted]
    moved = dock.profiles[1]
    a2, b2 = (v.astype(float) * SCALE + ORIGIN for v in lines.data[1])
    assert not np.allclose(moved["values"], before)
    assert a2[1] == pytest.approx(xz[0][1] + 5 * SCALE[1], abs=1e-5)
    np.testing.assert_allclose(moved["values"], _expected(data, a2, b2, moved["distance_um"]), atol=1e-6)
    assert len(dock.axes.lines) == 2 and dock.axes.get_xlabel() == "distance (µm)"
    # CSV export: every sample, distance and coordinates in µm
    out = dock.export_csv(tmp_path / "profiles.csv")
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == sum(len(p["values"]) for p in dock.profiles)
    last = [r for r in rows if r["line"] == "1"][-1]
    assert float(last["value"]) == pytest.approx(float(moved["values"][-1]), abs=1e-7)
    assert float(last["z_um"]) == pytest.approx(b2[0]) and float(last["y_um"]) == pytest.approx(b2[1])


def test_time_series_profile_follows_the_slider(make_napari_viewer):
    viewer = make_napari_viewer()
    series = np.stack([_volume(seed=s) for s in range(3)])
    img = viewer.add_image(
        series, scale=(1.0,) + SCALE, translate=(0.0,) + ORIGIN, name="cells RI", axis_labels=("t", "z", "y", "x")
    )
    dock = ProfileWidget(viewer)
    viewer.window.add_dock_widget(dock)
    dock.image.value = img
    lines = dock.new_line_layer()  # 3D lines: shown at every t
    a, b = np.array([-20.0, 0.0, 0.0]), np.array([20.0, 0.0, 0.0])  # along z through the centre
    lines.add_lines(np.stack([(a - ORIGIN) / SCALE, (b - ORIGIN) / SCALE]))
    a, b = (v.astype(float) * SCALE + ORIGIN for v in lines.data[0])
    for t in (0, 2):
        viewer.dims.set_current_step(0, t)
        p = dock.profiles[0]
        assert p["orientation"] == "axial (z)"
        np.testing.assert_allclose(p["values"], _expected(series[t], a, b, p["distance_um"]), atol=1e-6)


def test_sample_line_checks_its_input():
    vol = _volume((5, 8, 8))
    s, coords, v = sample_line(vol, (1, 2, 2), (1, 2, 6))
    assert len(s) == 5 and np.allclose(v, vol[1, 2, 2:7])  # on the grid: the voxel values
    assert orientation((0, 0, 0), (0, 0, 1), ["z", "y", "x"]) == "along x"
    from napari_ssdpc.errors import SsdpcError

    with pytest.raises(SsdpcError, match="coordinates"):
        sample_line(vol, (1, 2), (1, 3))
