"""The Optics widget: load, edit and save the instrument; the design numbers update live."""

from __future__ import annotations

import textwrap

from magicgui.widgets import CheckBox, FileEdit, FloatSpinBox, Label, LineEdit, PushButton, SpinBox

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.widgets.common import StepWidget, catching_warnings, wrap
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.design import design, design_warnings
from napari_ssdpc.settings.optics import Optics

__all__ = ["OPTICS_FIELDS", "OpticsWidget", "design_text"]

# attribute, label, tooltip, (min, max, step) or "int"/"bool"
OPTICS_FIELDS = [
    (
        "wavelength_um",
        "wavelength (µm)",
        "vacuum wavelength of the illumination, µm (520 nm = 0.52)",
        (0.2, 2.0, 0.001),
    ),
    (
        "medium_index",
        "medium index",
        "refractive index of the immersion / embedding medium (no unit)",
        (1.0, 2.5, 0.001),
    ),
    (
        "condenser_na",
        "condenser NA",
        "illumination NA (no unit); must stay below the objective NA (σ < 1) for phase contrast",
        (0.0, 1.6, 0.01),
    ),
    ("magnification", "objective M", "objective magnification (×)", (1.0, 200.0, 1.0)),
    ("na", "objective NA", "objective numerical aperture (no unit)", (0.01, 1.7, 0.01)),
    ("tube_lens_mm", "tube lens (mm)", "focal length of the tube lens, mm", (20.0, 1000.0, 1.0)),
    ("fourier_lens_mm", "Fourier lens (mm)", "focal length of the Fourier lens f_fl, mm", (5.0, 2000.0, 0.5)),
    ("pitch_um", "MLA pitch (µm)", "microlens pitch, µm", (10.0, 10000.0, 1.0)),
    ("mla_focal_length_mm", "MLA focal length (mm)", "microlens focal length f_ml, mm", (0.1, 500.0, 0.1)),
    ("lenslet_radius_um", "lenslet radius (µm)", "clear radius of one microlens, µm", (5.0, 10000.0, 1.0)),
    ("pixel_um", "camera pixel (µm)", "camera pixel size, µm", (0.5, 50.0, 0.01)),
    ("width_px", "sensor width (px)", "sensor width, pixels", "int"),
    ("height_px", "sensor height (px)", "sensor height, pixels", "int"),
    (
        "iris_radius_um",
        "iris radius (µm)",
        "field-iris radius at the native image plane, µm; 0 = EIs tangent (paper Eq. 9)",
        (0.0, 100000.0, 1.0),
    ),
    ("flip_x", "camera flipped in x", "the camera image is mirrored left-right", "bool"),
    ("flip_y", "camera flipped in y", "the camera image is mirrored up-down", "bool"),
]


def design_text(optics: Optics) -> str:
    """The design numbers (paper Eqs. 8-14), a few short lines.

    Parameters
    ----------
    optics : Optics

    Returns
    -------
    str
    """
    d = design(optics)
    return "\n".join(
        [
            f"FOV {d['fov_um']:.1f} µm · R_xy {d['r_xy_um']:.2f} µm",
            f"R_z {d['r_z_ffl_um']:.2f} µm (tanθ = √2·d/f_fl: matches the",
            f"    paper's measured 21.96 µm); {d['r_z_printed_um']:.2f} µm with Eq. 13 as printed",
            f"DOF {d['dof_full_um']:.1f} µm full width (FWHM {d['dof_fwhm_um']:.1f} µm)",
            f"usable depth {d['dof_um']:.1f} µm",
            f"lenslets: {d['lenslets_in_pupil']} in the pupil, {d['lenslets_usable']} usable (≥ 50 % inside)",
            f"source disk: {d['lenslets_inside']} inside, {d['lenslets_straddling']} straddling, "
            f"{d['lenslets_outside']} outside",
            f"σ {d['sigma']:.2f} · M_EI {d['m_ei']:.3f} · object pixel {d['object_pixel_um']:.4f} µm",
            f"pitch {d['pitch_px']:.2f} px · EI radius {d['ei_radius_px']:.2f} px",
            f"expected axial FWHM {d['expected_axial_fwhm_um']:.1f} µm from the {d['lenslets_straddling']} "
            "lenslets that straddle the source edge",
            *("⚠ " + w for w in design_warnings(optics)),
        ]
    )


class OpticsWidget(StepWidget):
    """Load, edit and save the optics; the design numbers update live."""

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer)
        self.fields = {}
        for attr, label, tip, spec in OPTICS_FIELDS:
            if spec == "bool":
                w = CheckBox(text=label, tooltip=tip)
            elif spec == "int":
                w = SpinBox(label=label, tooltip=tip, min=16, max=100000, step=1)
            else:
                w = FloatSpinBox(label=label, tooltip=tip, min=spec[0], max=spec[1], step=spec[2])
            self.fields[attr] = w
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
        self.design.value = design_text(optics)

    def values(self) -> dict:
        """The fields' values.

        Returns
        -------
        dict
            Flat optics attributes (``Optics.replace`` keywords).
        """
        v = {attr: w.value for attr, w in self.fields.items()}
        v["iris_radius_um"] = v["iris_radius_um"] or None
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
        self.design.value = design_text(optics)
        self.session.set_optics(optics)

    def set_optics(self, optics: Optics):
        """Show ``optics`` and make it the session's (the other widgets reset their defaults).

        Parameters
        ----------
        optics : Optics
        """
        self._show(optics)
        self.session.set_optics(optics, loaded=True)

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
            self.set_optics(catching_warnings(Optics.from_dict, d, source=f"layer '{layer.name}'"))
        except SsdpcError as e:
            notify.error(e)
