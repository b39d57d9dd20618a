"""The Optics widget: load, edit and save the instrument; the design numbers update live."""

from __future__ import annotations

import textwrap

from magicgui.widgets import CheckBox, FileEdit, FloatSpinBox, Label, LineEdit, PushButton, SpinBox

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.widgets.common import StepWidget, catching_warnings, wrap
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.design import design_table
from napari_ssdpc.settings.base import field_range
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.parts import PART_KEYS

__all__ = ["OPTICS_FIELDS", "OpticsWidget", "optics_field"]

# flat attribute (as Optics.replace takes it), label, spin-box step (None: a whole number or a switch);
# the range, the tooltip and the value that stands for "not set" come from the settings model
OPTICS_FIELDS = [
    ("wavelength_um", "wavelength (µm)", 0.001),
    ("medium_index", "medium index", 0.001),
    ("condenser_na", "condenser NA", 0.01),
    ("magnification", "objective M", 1.0),
    ("na", "objective NA", 0.01),
    ("tube_lens_mm", "tube lens (mm)", 1.0),
    ("fourier_lens_mm", "Fourier lens (mm)", 0.5),
    ("pitch_um", "MLA pitch (µm)", 1.0),
    ("mla_focal_length_mm", "MLA focal length (mm)", 0.1),
    ("lenslet_radius_um", "lenslet radius (µm)", 1.0),
    ("pixel_um", "camera pixel (µm)", 0.01),
    ("width_px", "sensor width (px)", None),
    ("height_px", "sensor height (px)", None),
    ("iris_radius_um", "iris radius (µm)", 1.0),
    ("flip_x", "camera flipped in x", None),
    ("flip_y", "camera flipped in y", None),
]


def optics_field(attr: str):
    """The settings field behind a flat :class:`Optics` attribute, and its inclusive range.

    Parameters
    ----------
    attr : str
        A flat attribute, e.g. ``"na"`` (in ``objective``) or ``"mla_focal_length_mm"``.

    Returns
    -------
    info : pydantic.fields.FieldInfo
        The field (its annotation, description and default).
    lo, hi : float
        Its range (``settings.base.field_range``); ±inf where it has none.
    """
    model, name = Optics, attr
    if attr in PART_KEYS:
        part, name = PART_KEYS[attr]
        model = Optics.model_fields[part].annotation
    lo, hi = field_range(model, name)
    return model.model_fields[name], lo, hi


def _field_widget(attr: str, label: str, step):
    """A spin box or check box with the field's range and description; an optional number shows
    its "not set" value (the model's default, None) as 0."""
    info, lo, hi = optics_field(attr)
    tip = info.description
    if info.annotation is bool:
        return CheckBox(text=label, tooltip=tip)
    if info.annotation is int:
        return SpinBox(label=label, tooltip=tip, min=int(lo), max=int(hi), step=1)
    if info.is_required():
        return FloatSpinBox(label=label, tooltip=tip, min=lo, max=hi, step=step)
    return FloatSpinBox(label=label, tooltip=f"{tip}; 0 = not set, else {lo:g} to {hi:g}", min=0.0, max=hi, step=step)


class OpticsWidget(StepWidget):
    """Load, edit and save the optics; the design numbers update live."""

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer)
        self.fields = {attr: _field_widget(attr, label, step) for attr, label, step in OPTICS_FIELDS}
        self.name = LineEdit(label="name", tooltip="a name for this instrument (free text)")
        self.path = FileEdit(mode="r", filter="*.yaml *.yml")
        self.path.label = "optics YAML"
        self.path.tooltip = "optics file in the schema of docs/paper-optics.yaml (lengths carry their unit)"
        self.load_button = PushButton(text="Load YAML", tooltip="read the optics from the YAML file above")
        self.save_button = PushButton(text="Save YAML…", tooltip="write the optics to a YAML file")
        self.paper_button = PushButton(text="Paper optics", tooltip="the paper's instrument (20×/0.4, f_fl 75 mm)")
        self.layer_button = PushButton(
            text="From selected layer", tooltip="adopt the optics stored with the selected layer (sample data)"
        )
        self.design = wrap(Label(value=""))
        self.design.tooltip = "design numbers of paper Eqs. 8-14 (µm)"
        self.extend(
            [
                self.path,
                self.load_button,
                self.save_button,
                self.paper_button,
                self.layer_button,
                self.name,
                *self.fields.values(),
                self.design,
            ]
        )
        self._last_error = None
        self._updating = False
        self._show(self.session.optics)
        for w in [*self.fields.values(), self.name]:
            w.changed.connect(self._edited)
        self.load_button.changed.connect(self.load)
        self.save_button.changed.connect(self._save_dialog)
        self.paper_button.changed.connect(lambda *_: self.set_optics(Optics.paper()))
        self.layer_button.changed.connect(self._from_layer)
        self.session.optics_loaded.connect(self._show)
        self.session.optics_adopted.connect(self._show)

    # ----------------------------------------------------------------------------
    def _show(self, optics: Optics):
        """Fill the fields from ``optics`` without triggering edits."""
        self._updating = True
        try:
            for attr, w in self.fields.items():
                v = getattr(optics, attr)
                w.value = 0.0 if v is None else v
            self.name.value = optics.name
        finally:
            self._updating = False
        self.design.value = design_table(optics, short=True)

    def values(self) -> dict:
        """The fields' values.

        Returns
        -------
        dict
            Flat optics attributes (``Optics.replace`` keywords).
        """
        v = {attr: w.value for attr, w in self.fields.items()}
        for attr in v:
            info = optics_field(attr)[0]
            if not info.is_required() and info.default is None and not v[attr]:
                v[attr] = None  # 0 in the spin box: not set
        v["name"] = self.name.value
        return v

    def _edited(self, *_):
        if self._updating:
            return
        try:
            optics = catching_warnings(self.session.optics.replace, **self.values())
        except SsdpcError as e:
            self.design.value = "⚠ " + "\n".join(textwrap.wrap(str(e), 60))
            if str(e) != self._last_error:
                notify.error(str(e))
            self._last_error = str(e)
            return
        self._last_error = None
        self.design.value = design_table(optics, short=True)
        self.session.set_optics(optics)

    def set_optics(self, optics: Optics, reset: bool = True):
        """Show ``optics`` and make it the session's.

        Parameters
        ----------
        optics : Optics
        reset : bool
            The other widgets go back to their defaults (a new instrument: Load YAML); False keeps
            the z range, method and α the user set (the optics of a layer already being worked on).
        """
        self._show(optics)
        self.session.set_optics(optics, loaded=reset)

    def load(self, *_):
        """Read the optics YAML named in the path field."""
        try:
            self.set_optics(catching_warnings(Optics.from_yaml, self.path.value))
        except SsdpcError as e:
            notify.error(e)

    def save(self, path):
        """Write the session's optics as YAML.

        Parameters
        ----------
        path : str or Path
        """
        try:
            self.session.optics.to_yaml(path)
        except OSError as e:
            notify.error(f"could not write {path}: {e.strerror}; choose a writable folder")

    def _save_dialog(self, *_):
        from magicgui.widgets import request_values

        got = request_values(
            path={"annotation": "pathlib.Path", "options": {"mode": "w", "filter": "*.yaml"}}, title="Save optics YAML"
        )
        if got and got.get("path"):
            self.save(got["path"])

    def _from_layer(self, *_):
        layer = self.viewer.layers.selection.active
        d = None if layer is None else layer.metadata.get("ssdpc", {}).get("optics")
        if d is None:
            notify.error("the selected layer carries no optics; select a sample-data layer or load a YAML")
            return
        try:
            optics = catching_warnings(Optics.from_dict, d, source=f"layer '{layer.name}'")
            self.set_optics(optics, reset=False)  # the user's z range, method and α stay
        except SsdpcError as e:
            notify.error(e)
