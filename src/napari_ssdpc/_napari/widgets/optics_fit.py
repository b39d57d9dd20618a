"""The Calibrate tab's "Fit the optics" step: the condenser's NA and centre from a flat frame layer,
each view's |focus| from the white frame layer and the objective's aberration and the views' defocus
from a frame of beads, as `ssdpc fit-optics` does (docs/aberrations.md)."""

from __future__ import annotations

import numpy as np
from magicgui.widgets import FloatSpinBox, Label

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.layers import calibration_layers
from napari_ssdpc._napari.widgets.choices import LayerChoice, calibration_layer_choices, image_layer_choices
from napari_ssdpc._napari.widgets.common import (
    StepWidget,
    follow_layers,
    frame_index,
    run_buttons,
    show_in_turns,
    wrap,
)
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc._napari.widgets.session import calibration_of

__all__ = ["OpticsFitWidget"]

#: The end of a calibration layer's name: the fitted one is named after the same stem.
_CIRCLES = " EI circles"


class OpticsFitWidget(StepWidget):
    """Fit the instrument to the user's frames: a copy of the calibration with the fitted condenser
    (shown as new calibration layers, which the Method tab then takes), and the fit's report."""

    def __init__(self, napari_viewer, scrollable: bool = True):
        super().__init__(napari_viewer, scrollable=scrollable)
        self.calibration = LayerChoice(
            label="calibration",
            choices=calibration_layer_choices(napari_viewer),
            tooltip="the calibration to fit the optics of (default: the newest)",
        )
        self.flat = LayerChoice(
            label="flat frame",
            choices=image_layer_choices(napari_viewer, prefer="flat"),
            tooltip="flat frame (no sample, the raw frames' condenser setting): the condenser's NA and centre",
        )
        self.white = LayerChoice(
            label="white frame",
            choices=image_layer_choices(napari_viewer, allow_none="none", prefer="white"),
            tooltip="white frame (condenser open): each view's focus from its elemental images' rims; none: skip",
        )
        self.beads = LayerChoice(
            label="bead frame",
            choices=image_layer_choices(napari_viewer, allow_none="none", prefer="none"),  # none by default
            tooltip="a raw frame of beads: the objective's aberration and every view's defocus, the beads' centres "
            "and sizes free (minutes); none: skip",
        )
        self.bead_ri = FloatSpinBox(
            label="bead RI (0: unknown)",
            min=0.0,
            max=3.0,
            step=0.001,
            value=0.0,
            tooltip="the beads' refractive index, when known (held in the fit); the medium is the optics'",
        )
        self.run_button, self.cancel_button, self.status = run_buttons(
            "Fit the optics",
            "fit the condenser's NA and centre to the flat frame (the views' focus, the pupil to beads)",
        )
        self.result = wrap(Label(value=""))
        self.result.tooltip = "each fitted term with its uncertainty, the misfit before and after"
        self.extend([self.calibration, self.flat, self.white, self.beads, self.bead_ri])
        self.extend([self.run_button, self.cancel_button, self.status])
        self.append(self.result)
        self.runner = JobRunner("Fit the optics", self.run_button, self.cancel_button, self.status)
        self.run_button.changed.connect(self.run)
        follow_layers(napari_viewer, self)

    def run(self, *_):
        """Fit in a worker; the fitted calibration's layers and the report when done."""
        cal_layer, flat_layer, white_layer = self.calibration.value, self.flat.value, self.white.value
        bead_layer, bead_ri = self.beads.value, float(self.bead_ri.value) or None
        if cal_layer is None or flat_layer is None:
            notify.error("fitting the optics needs a calibration and a flat frame: calibrate, and open the flat frame")
            return None
        cal, optics = calibration_of(cal_layer), self.session.optics
        frames = [
            None if lyr is None else (lyr.data, frame_index(self.viewer, lyr))
            for lyr in (flat_layer, white_layer, bead_layer)
        ]
        config = self.session.config() if bead_layer is not None else None

        def work(progress, should_stop):
            from napari_ssdpc.reconstruction.optics_fit import BeadFrame, fit_optics

            flat, white, raw = (None if f is None else np.asarray(f[0] if f[1] is None else f[0][f[1]]) for f in frames)
            progress(0, 1, "fitting the condenser")
            beads = None if raw is None else BeadFrame(config, raw, bead_ri, bead_layer.name)
            return fit_optics(cal, flat, optics, white, progress=progress, beads=beads, should_stop=should_stop)

        stem = cal_layer.name.removesuffix(_CIRCLES)
        return self.runner.start(work, lambda fit: self._done(fit, f"{stem} fitted"), "Fit the optics")

    def _done(self, fit, name: str):
        show_in_turns(self.viewer, calibration_layers(fit.calibration, name))
        self.result.value = "\n".join(fit.report())
        return f"fitted: '{name}{_CIRCLES}'"
