"""The Operators widget: z range, method and its settings; builds the operators once."""

from __future__ import annotations

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, FloatSpinBox, PushButton, SpinBox

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.layers import result_layer
from napari_ssdpc._napari.widgets.choices import LayerChoice, calibration_layer_choices
from napari_ssdpc._napari.widgets.common import (
    StepWidget,
    follow_layers,
    run_buttons,
    show_layer,
)
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc._napari.widgets.session import calibration_of
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.methods import METHODS
from napari_ssdpc.settings.base import field_range
from napari_ssdpc.settings.reconstruction import (
    SIGNS,
    TRANSFER_MODELS,
    ReconstructionSettings,
    TvSettings,
)

__all__ = ["OperatorsWidget"]


def _spin_box(rec: ReconstructionSettings, name: str, label: str, step: float, tooltip: str) -> FloatSpinBox:
    """A spin box over a field of the reconstruction settings: its range, its value in ``rec``."""
    lo, hi = field_range(ReconstructionSettings, name)
    return FloatSpinBox(label=label, min=lo, max=hi, step=step, value=getattr(rec, name), tooltip=tooltip)


class OperatorsWidget(StepWidget):
    """z range, dz and model; builds the PSFs and transfer functions once (a Reconstructor)."""

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer, "operators_widget")
        rec = ReconstructionSettings()
        self.calibration = LayerChoice(
            label="calibration",
            choices=calibration_layer_choices(napari_viewer),
            tooltip="EI-circles layer made by Calibrate or opened from a calibration JSON (default: the newest)",
        )
        self.z_min = _spin_box(
            rec, "z_min_um", "z min (µm)", 1, "first plane, µm from the focal plane (z > 0: farther from the objective)"
        )
        self.z_max = _spin_box(rec, "z_max_um", "z max (µm)", 1, "last plane, µm from the focal plane")
        self.dz = _spin_box(
            rec, "dz_um", "dz (µm)", 0.05, "plane spacing, µm (the paper's axial resolution is about 21 µm)"
        )
        self.model = ComboBox(
            label="transfer model",
            choices=list(TRANSFER_MODELS),
            value=rec.rl.model,
            tooltip="lenslet: the MLA splits the detection pupil (default); paper: half-disk "
            "sources as in the paper's Eq. 4",
        )
        self.method = ComboBox(
            label="phase method",
            choices=list(METHODS),
            value=rec.method,
            tooltip="; ".join(f"{name}: {entry.summary}" for name, entry in METHODS.items()),
        )
        fields = TvSettings.model_fields
        self.sign = ComboBox(
            label="sign of Δn (tv)", choices=list(SIGNS), value=rec.tv.sign, tooltip=fields["sign"].description
        )
        lo, hi = field_range(TvSettings, "lambda_scale")
        self.tv_lambda = FloatSpinBox(
            label="TV weight (tv)",
            min=0.0,
            max=hi,
            step=0.1,
            value=0.0,
            tooltip=f"{fields['lambda_scale'].description}; 0 = automatic, else {lo:g} to {hi:g}",
        )
        lo, hi = field_range(TvSettings, "iterations")
        self.tv_iterations = SpinBox(
            label="TV iterations (tv)",
            min=int(lo),
            max=int(hi),
            value=rec.tv.iterations,
            tooltip=fields["iterations"].description,
        )
        self.stacks = CheckBox(
            text="directional stacks (Richardson–Lucy)",
            value=False,
            tooltip="also deconvolve the four halves: needed for DPC, stacks, absorption and the PSF view",
        )
        self.run_button, self.cancel_button, self.status = run_buttons(
            "Build operators", "compute the PSFs and transfer functions"
        )
        self.lenslet = ComboBox(
            label="PSF of lenslet",
            choices=self._lenslet_choices,
            tooltip="(row, col) of a lit lenslet of the built operators",
        )
        self.psf_button = PushButton(
            text="Show PSF stack", tooltip="add this lenslet's PSF (z, y, x) as a layer (scale in µm)"
        )
        self.extend(
            [
                self.calibration,
                self.z_min,
                self.z_max,
                self.dz,
                self.model,
                self.method,
                self.sign,
                self.tv_lambda,
                self.tv_iterations,
                self.stacks,
                self.run_button,
                self.cancel_button,
                self.status,
                self.lenslet,
                self.psf_button,
            ]
        )
        self.runner = JobRunner("Operators", self.run_button, self.cancel_button, self.status)
        self.run_button.changed.connect(self.run)
        self.psf_button.changed.connect(self.show_psf)
        self.session.optics_loaded.connect(self._defaults)
        self.session.settings_loaded.connect(self.show_settings)
        self.session.optics_changed.connect(self._stale)
        self.session.operators_built.connect(self._refresh_lenslets)
        follow_layers(napari_viewer, self)

    def _defaults(self, optics):
        rec = ReconstructionSettings()
        self.z_min.value, self.z_max.value, self.dz.value = rec.z_min_um, rec.z_max_um, rec.dz_um
        self.model.value, self.method.value = rec.rl.model, rec.method

    def show_settings(self, rec: ReconstructionSettings) -> None:
        """Show loaded reconstruction settings (z grid, model, method, the 'tv' parameters).

        Parameters
        ----------
        rec : ReconstructionSettings
        """
        self.z_min.value, self.z_max.value, self.dz.value = rec.z_min_um, rec.z_max_um, rec.dz_um
        self.model.value, self.method.value, self.sign.value = rec.rl.model, rec.method, rec.tv.sign
        self.tv_lambda.value = rec.tv.lambda_scale or 0.0
        self.tv_iterations.value = rec.tv.iterations

    def _stale(self, _optics):
        if self.session.built is not None and not self.runner.running:
            self.status.value = "optics changed: the operators are rebuilt at the next run"

    def _refresh_lenslets(self, _rec):
        self.lenslet.reset_choices()

    def _lenslet_choices(self, _widget=None):
        rec = self.session.built[1] if self.session.built else None
        if rec is None:
            return []
        return [(f"({ln.row}, {ln.col})", i) for i, ln in enumerate(rec.lenslets)]

    def settings_changes(self) -> dict:
        """The reconstruction keys this widget shows (see :meth:`Session.settings`).

        Returns
        -------
        dict
            z grid, method, the DPC model and the 'tv' section's keys.
        """
        return {
            "z_min_um": float(self.z_min.value),
            "z_max_um": float(self.z_max.value),
            "dz_um": float(self.dz.value),
            "method": self.method.value,
            "rl": {"model": self.model.value},
            "tv": {
                "sign": self.sign.value,
                "lambda_scale": float(self.tv_lambda.value) or None,
                "iterations": int(self.tv_iterations.value),
            },
        }

    def inputs(self) -> dict:
        """The calibration and whether to compute the directional stacks (see :meth:`Session.job`)."""
        layer = self.calibration.value
        return {"calibration": None if layer is None else calibration_of(layer), "stacks": bool(self.stacks.value)}

    def run(self, *_):
        """Build the operators (a Reconstructor) in a worker."""
        try:
            job = self.session.job()
            self.session.remember()
        except SsdpcError as e:
            notify.error(e)
            return None
        if self.session.matching(job) is not None:  # the same settings, calibration and flat: nothing to build
            self.status.value = f"up to date: {self._built_text(job, self.session.built[1])}"
            return None

        def work(progress, should_stop):
            return job.build(progress)

        return self.runner.start(work, lambda rec: self._done(job, rec), "Operators")

    def _built_text(self, job, rec) -> str:
        widget = self.session.reconstruct_widget() if self.session.reconstruct_widget else None
        flat = getattr(getattr(widget, "flat", None), "value", None)
        with_flat = f"flat '{flat.name}'" if job.flat is not None and flat is not None else "no flat"
        return (
            f"{len(rec.z_um)} planes {rec.z_um[0]:g}…{rec.z_um[-1]:g} µm, {len(rec.lenslets)} lit lenslets, "
            f"{with_flat}, α {rec.config.reconstruction.alpha:g}"
        )

    def _done(self, job, rec):
        self.session.built = (job, rec)
        self.session.operators_built.emit(rec)
        return f"built in {rec.build_seconds:.1f} s: {self._built_text(job, rec)}"

    def show_psf(self, *_):
        """Add the chosen lenslet's PSF stack (z, y, x) as a layer in µm, computed in a worker."""
        rec = self.session.built[1] if self.session.built else None
        if rec is None or rec.stacks is None:
            notify.error("no PSF operators: tick 'directional stacks' and press Build operators first")
            return None
        k = self.lenslet.value or 0
        ln = rec.lenslets[k]

        def work(progress, should_stop):
            out = []
            for i, z in enumerate(rec.z_um):
                out.append(rec.stacks.psf.kernels(float(z))[k])
                progress(i + 1, len(rec.z_um), "PSF")
            stack = np.stack(out)
            info = {"source": f"lenslet ({ln.row}, {ln.col})", "medium_index": rec.optics.medium_index}
            return result_layer(  # its display limits read the data: here, not on the GUI thread
                stack,
                "psf",
                (rec.dz, rec.pixel_um, rec.pixel_um),
                (rec.z_um[0], -(stack.shape[1] // 2) * rec.pixel_um, -(stack.shape[2] // 2) * rec.pixel_um),
                name=f"lenslet ({ln.row}, {ln.col})",
                info=info,
            )

        def done(layer):
            data, kwargs, _ = layer
            show_layer(self.viewer, data, kwargs)
            return f"PSF of lenslet ({ln.row}, {ln.col})"

        return self.runner.start(work, done, "PSF")
