"""The Optics widget takes every range from the settings model, so the two never disagree."""

from __future__ import annotations

import math

import pytest

from napari_ssdpc.physics.design import design_table
from napari_ssdpc.settings.base import field_range
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.parts import MLA, Objective, Sensor

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import widgets as _widgets
from napari_ssdpc._napari.widgets.optics import OPTICS_FIELDS, optics_field

#: Where each flat attribute is defined, written out here so that the test does not use the
#: lookup it checks.
MODELS = {
    **{k: (Optics, k) for k in ("wavelength_um", "medium_index", "condenser_na", "fourier_lens_mm")},
    **{k: (Optics, k) for k in ("iris_radius_um", "flip_x", "flip_y")},
    **{k: (Objective, k) for k in ("magnification", "na", "tube_lens_mm")},
    "pitch_um": (MLA, "pitch_um"),
    "mla_focal_length_mm": (MLA, "focal_length_mm"),
    "lenslet_radius_um": (MLA, "lenslet_radius_um"),
    **{k: (Sensor, k) for k in ("pixel_um", "width_px", "height_px")},
}


def test_every_optics_field_is_in_the_widget():
    assert sorted(a for a, _, _ in OPTICS_FIELDS) == sorted(MODELS)


@pytest.mark.parametrize("attr", sorted(MODELS))
def test_optics_field_finds_the_models_range(attr):
    model, name = MODELS[attr]
    info, lo, hi = optics_field(attr)
    assert info is model.model_fields[name]
    assert (lo, hi) == field_range(model, name)


def test_the_widgets_ranges_are_the_models(make_napari_viewer):
    ow = _widgets.OpticsWidget(make_napari_viewer())
    for attr, w in ow.fields.items():
        model, name = MODELS[attr]
        lo, hi = field_range(model, name)
        if math.isinf(lo):  # a switch
            assert isinstance(w.value, bool)
            continue
        info = model.model_fields[name]
        assert w.max == hi, attr
        # an optional number (the iris) shows "not set" as 0, below its range
        assert w.min == (lo if info.is_required() else 0.0), attr
    ow.fields["iris_radius_um"].value = 0.0
    assert ow.values()["iris_radius_um"] is None
    ow.fields["iris_radius_um"].value = 600.0
    assert ow.values()["iris_radius_um"] == 600.0


def test_the_widget_shows_the_short_design_table(make_napari_viewer):
    ow = _widgets.OpticsWidget(make_napari_viewer())
    optics = Optics.paper()
    ow.set_optics(optics)
    assert ow.design.value == design_table(optics, short=True)
    assert "FOV 122.5 µm" in ow.design.value and "Field of view D_FOV (Eq. 10)" in design_table(optics)


@pytest.mark.parametrize("dock_first", [True, False], ids=["dock, then sample", "sample, then dock"])
def test_the_sample_brings_its_own_optics(make_napari_viewer, qtbot, monkeypatch, tmp_path, dock_first):
    """The bead sample is simulated at condenser NA 0.3 (the paper optics have 0.1) on a 1024 px
    region: opening it makes those the optics, in either order, and the tabs show them; the z range,
    method and α set before stay."""
    from napari_ssdpc._napari import notify
    from napari_ssdpc._napari.sample_data import bead_frames

    notes = []
    monkeypatch.setattr(notify, "info", lambda msg: notes.append(str(msg)))
    monkeypatch.setenv("NAPARI_SSDPC_CONFIG", str(tmp_path))  # nothing remembered from other tests
    viewer = make_napari_viewer()
    if dock_first:
        _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
        assert dock.session.optics == Optics.paper()
        op, rc = dock.tabs["Method"], dock.tabs["Reconstruct"]
        op.z_min.value, op.z_max.value, op.dz.value, op.method.value = -12.0, 18.0, 3.0, "wotf"
        rc.alpha.value = 0.05
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    if not dock_first:
        _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    else:  # the user's settings stay
        assert (op.z_min.value, op.z_max.value, op.dz.value, op.method.value, rc.alpha.value) == (
            -12.0, 18.0, 3.0, "wotf", 0.05
        )  # fmt: skip
    optics = bead_frames()[3]
    assert Optics.paper().condenser_na == 0.1 and optics.condenser_na == 0.3
    assert dock.session.optics == optics
    w = dock.tabs["Optics"]
    assert w.fields["condenser_na"].value == 0.3 and w.fields["width_px"].value == optics.width_px == 1024
    assert sum("adopted" in n for n in notes) == 1 and "condenser NA 0.3" in notes[-1]
    # an edit after opening is kept: the optics are adopted when frames arrive, not again and again
    w.fields["condenser_na"].value = 0.25
    viewer.add_image(viewer.layers["PMMA bead"].data[:8, :8], name="crop")  # no optics: nothing adopted
    assert dock.session.optics.condenser_na == 0.25 and sum("adopted" in n for n in notes) == 1


def test_from_selected_layer_adopts_the_optics_and_keeps_the_users_settings(make_napari_viewer, monkeypatch, tmp_path):
    """'From selected layer' takes the layer's optics; the z range, method and α the user set stay."""
    from napari_ssdpc._napari.sample_data import bead_frames

    monkeypatch.setenv("NAPARI_SSDPC_CONFIG", str(tmp_path))  # nothing remembered from other tests
    viewer = make_napari_viewer()
    _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    frame, _, _, optics = bead_frames()
    layer = viewer.add_image(frame, name="bead", metadata={"ssdpc": {"optics": optics.to_dict()}})
    ow, op, rc = (dock.tabs[name] for name in ("Optics", "Method", "Reconstruct"))
    ow.set_optics(Optics.paper())  # another instrument loaded after the frame arrived
    op.z_min.value, op.z_max.value, op.dz.value, op.method.value = -12.0, 18.0, 3.0, "wotf"
    rc.alpha.value = 0.05
    viewer.layers.selection.active = layer
    ow.layer_button.clicked.emit()
    assert dock.session.optics == optics and ow.fields["condenser_na"].value == optics.condenser_na
    assert (op.z_min.value, op.z_max.value, op.dz.value, op.method.value) == (-12.0, 18.0, 3.0, "wotf")
    assert rc.alpha.value == 0.05
