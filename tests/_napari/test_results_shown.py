"""Results shown so they can be trusted: contrast limits that span the object, µm on every layer the
plugin adds, the first result brought into view however it arrives, the axial resolution with it."""

from __future__ import annotations

import numpy as np
import pytest

from napari_ssdpc._napari.layers import axial_fwhm_um, object_extremes, result_layer
from napari_ssdpc.physics.design import design
from napari_ssdpc.settings.optics import Optics

MEDIUM = 1.518
VOXEL = (2.0, 0.8456, 0.8456)  # (dz, dy, dx) µm, as the bead sample
SHAPE = (41, 145, 145)
ORIGIN = (-40.0, -72 * VOXEL[1], -72 * VOXEL[2])  # the optical axis at the centre


def _bead_volume():
    """RI of a bead peaking at Δn −0.019 (radius 6.5 µm laterally, 9.75 µm along z, a smooth profile as
    a reconstruction gives) with a weak axial trail (−0.003) above it, one hot voxel (+0.05) inside
    the field and a strong blob (+0.04) outside the field of view."""
    z, y, x = (ORIGIN[i] + VOXEL[i] * np.arange(SHAPE[i]) for i in range(3))
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    ri = np.full(SHAPE, MEDIUM, np.float32)
    r2 = ((zz / 1.5) ** 2 + yy**2 + xx**2) / 6.5**2
    ri -= np.where(r2 <= 1, 0.019 * (1 - r2), 0).astype(np.float32)
    ri[(zz > 10) & (zz < 30) & (yy**2 + xx**2 <= 4.0**2)] -= 0.003
    ri[20, 80, 60] += 0.05
    ri[20:23, :4, :4] += 0.04  # a corner: outside the 61 µm field radius
    return ri


def test_contrast_limits_span_the_strongest_object_inside_the_field():
    optics = Optics.paper().replace(condenser_na=0.3, width_px=1024, height_px=1024)
    assert optics.fov_um / 2 < np.hypot(ORIGIN[1], ORIGIN[2])  # the corner blob lies outside the field
    ri = _bead_volume()
    dev = ri - MEDIUM
    # a percentile over the whole volume follows the volume's size, not the object: it clips the bead
    assert np.percentile(np.abs(dev), 99.9) < 0.019 / 2
    a, above = object_extremes(dev, VOXEL, ORIGIN, optics.fov_um / 2)
    assert above == 0.0  # the hot voxel and the blob outside the field are no objects
    assert a == pytest.approx(-dev[:, 10:-10, 10:-10].min(), rel=1e-6)  # the bead's peak: no voxel of it clipped
    assert a == pytest.approx(0.019, rel=1e-3)  # not the hot voxel, not the blob outside the field
    _, kw, _ = result_layer(ri, "ri", VOXEL, ORIGIN, name="bead", info={"optics": optics.to_dict()})
    lo, hi = kw["contrast_limits"]
    assert (lo, hi) == pytest.approx((MEDIUM - a, MEDIUM + a), abs=1e-6)  # symmetric about the medium
    assert kw["rendering"] == "minip"  # lighter than the medium dominates
    assert kw["units"] == ("µm", "µm", "µm")
    info = kw["metadata"]["ssdpc"]
    assert info["axial_fwhm_um"] == pytest.approx(design(optics)["expected_axial_fwhm_um"])
    assert 20 < info["axial_fwhm_um"] < 26  # the measured FWHM of a 13 µm bead at NA 0.3 is 22 µm
    assert axial_fwhm_um(Optics.paper().replace(condenser_na=0.01)) > info["axial_fwhm_um"]


pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps  # noqa: E402  (the GUI tests below need napari)


def test_a_result_opened_from_a_file_is_brought_into_view_in_um(make_napari_viewer, qtbot, tmp_path):
    """File › Open of a result, no dock open: the frames are hidden, the view fits the volume, the
    scale bar is on and every layer is in µm."""
    from napari_ssdpc._napari import writer as _writer
    from napari_ssdpc._napari.placement import scale_bar

    viewer = make_napari_viewer()
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    optics = Optics.from_dict(viewer.layers["PMMA bead"].metadata["ssdpc"]["optics"])
    data, kw, _ = result_layer(
        _bead_volume(), "ri", VOXEL, ORIGIN, name="bead", info={"optics": optics.to_dict(), "source": "PMMA bead"}
    )
    [path] = _writer.write_volume(str(tmp_path / "bead.ome.tif"), data, kw)
    assert not scale_bar(viewer).visible
    [layer] = viewer.open(path, plugin="napari-ssdpc")
    assert not any(viewer.layers[n].visible for n in ("PMMA bead", "PMMA bead flat", "PMMA bead white"))
    assert layer.visible and scale_bar(viewer).visible
    assert scale_bar(viewer).position == "bottom_left"  # not under the notifications (bottom right)
    assert {str(u) for lyr in viewer.layers for u in lyr.units[-2:]} == {"micrometer"}
    # the view was fitted to the volume (123 µm wide), not left on the 866 µm frames
    assert _camera(viewer).zoom == pytest.approx(_fitted_zoom(viewer, layer), rel=1e-3)
    assert layer.metadata["ssdpc"]["axial_fwhm_um"] == pytest.approx(axial_fwhm_um(optics))
    # the status bar reads the RI to 4 decimals under the cursor (napari's 3 digits gave 1.5)
    centre = (0.0, 0.0, 0.0)
    status = layer.get_status(centre, world=True)
    truth = float(layer.data[tuple(np.round(layer.world_to_data(centre)).astype(int))])
    assert status["value"] == f"{truth:.4f}" and truth < MEDIUM - 0.015, (status, truth)
    assert status["coordinates"].endswith(f": {truth:.4f}")


def test_a_sample_opened_beside_other_layers_is_fitted_to_the_view(make_napari_viewer, qtbot):
    """napari fits the view to a viewer's first layers only: the bead sample opened after a large
    image was left far off view."""
    viewer = make_napari_viewer()
    viewer.add_image(np.zeros((64, 64), np.float32), scale=(200.0, 200.0), name="a large field")  # 12.8 mm
    [*_, bead] = viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    assert bead.name == "PMMA bead"
    assert _camera(viewer).zoom == pytest.approx(_fitted_zoom(viewer, bead), rel=1e-3)


def _fitted_zoom(viewer, layer):
    """The zoom napari's fit_to_view gives for ``layer`` alone."""
    zoom = _camera(viewer).zoom
    viewer.fit_to_view(layers=[layer])
    fitted, _camera(viewer).zoom = _camera(viewer).zoom, zoom
    return fitted


def test_the_profile_line_layer_is_in_the_images_um(make_napari_viewer):
    from napari_ssdpc._napari.profiles import ProfileWidget

    viewer = make_napari_viewer()
    data, kw, _ = result_layer(_bead_volume(), "ri", VOXEL, ORIGIN, name="bead", info={"medium_index": MEDIUM})
    img = viewer.add_image(data, **kw)
    dock = ProfileWidget(viewer)
    viewer.window.add_dock_widget(dock, name="profile")
    lines = dock.new_line_layer()
    assert lines.units == img.units and {str(u) for u in lines.units} == {"micrometer"}
    assert viewer.layers.units is not None  # napari found the units consistent (no "Inconsistent units")


def _camera(viewer):
    """The viewer's camera (``viewer.scene.camera`` since napari 0.9)."""
    scene = getattr(viewer, "scene", None)
    return scene.camera if scene is not None else viewer.camera
