"""The Calibrate widget: find the lenslet lattice and the optical axis on a frame layer."""

from __future__ import annotations

import numpy as np
from magicgui.widgets import ComboBox, FileEdit, Label, PushButton

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.layers import calibration_layers
from napari_ssdpc._napari.widgets.choices import LayerChoice, image_layer_choices
from napari_ssdpc._napari.widgets.common import (
    StepWidget,
    follow_layers,
    frame_index,
    run_buttons,
    show_in_turns,
    wrap,
)
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc._napari.widgets.optics_fit import OpticsFitWidget
from napari_ssdpc.errors import SsdpcError

__all__ = ["CalibrateWidget", "guide_points"]


def guide_points(points, frame) -> np.ndarray:
    """The points of a Points layer as (x, y) pixels of a frame layer (the optical axis left out).

    Parameters
    ----------
    points : napari Points layer
        Clicked near EI centres, or a calibration's EI centres layer.
    frame : napari Image layer
        The (y, x) frame or (t, y, x) series calibrated on.

    Returns
    -------
    ndarray, (N, 2)
        (x, y) in the frame's pixels.
    """
    data = np.asarray(points.data, float).reshape(-1, points.ndim)
    labels = points.features.get("label") if len(points.features) else None
    if labels is not None:
        data = data[np.asarray(labels) != "axis"]
    world = [points.data_to_world(p) for p in data]
    pix = np.array([np.asarray(frame.world_to_data(np.r_[np.zeros(frame.ndim - len(w)), w]))[-2:] for w in world])
    return pix.reshape(-1, 2)[:, ::-1]


class CalibrateWidget(StepWidget):
    """Detect the lenslet grid on an image layer; adds EI circles and centres layers."""

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer)
        self.image = LayerChoice(
            label="frame",
            choices=image_layer_choices(napari_viewer, prefer="white"),
            tooltip="raw frame to calibrate on: best a white frame (condenser fully open); a "
            "flat or sample frame also works, less precisely (±0.5 px)",
        )
        self.kind = ComboBox(
            label="frame kind",
            choices=["auto", "white", "flat", "sample"],
            value="auto",
            tooltip="white: condenser fully open (σ = 1); flat/sample: the sample's condenser "
            "setting; auto: decided from the number of lit lenslets",
        )
        self.guide = ComboBox(
            label="guide points",
            choices=self._points_layers,
            tooltip="when detection fails or looks wrong: a Points layer with a point near the centre of "
            "each of a few EIs (or the EI centres of a calibration, dragged where they belong); the "
            "calibration refines from there. none: detect the EIs automatically",
        )
        self.guide_button = PushButton(
            text="Add guide points", tooltip="add a Points layer on the frame and click near EI centres"
        )
        self.run_button, self.cancel_button, self.status = run_buttons(
            "Calibrate", "find the lattice and the optical axis"
        )
        self.result = wrap(Label(value=""))
        self.result.tooltip = "optical axis position (px), lenslet pitch (px), MLA rotation (degrees)"
        self.path = FileEdit(mode="w", filter="*.json")
        self.path.label = "save as"
        self.path.tooltip = "calibration JSON to write (open it again with File > Open)"
        self.save_button = PushButton(text="Save calibration JSON", tooltip="write the last calibration to the path")
        self.extend(
            [
                self.image,
                self.kind,
                self.guide,
                self.guide_button,
                self.run_button,
                self.cancel_button,
                self.status,
                self.result,
                self.path,
                self.save_button,
            ]
        )
        self.runner = JobRunner("Calibrate", self.run_button, self.cancel_button, self.status)
        self.fit = OpticsFitWidget(napari_viewer, scrollable=False)  # the next step on these frames
        self.fit.label = "Fit the optics"
        self.append(self.fit)
        self.calibration = None
        self.run_button.changed.connect(self.run)
        self.guide_button.changed.connect(lambda *_: self.add_guide_points())
        self.save_button.changed.connect(lambda *_: self.save(self.path.value))
        follow_layers(napari_viewer, self)

    def run(self, *_):
        """Calibrate on the chosen frame layer (at the time slider for a series), in a worker."""
        layer = self.image.value
        if layer is None:
            notify.error("no image layer to calibrate: open a white frame (or the sample data) first")
            return None
        data, t, kind, optics = layer.data, frame_index(self.viewer, layer), self.kind.value, self.session.optics
        guess = None if self.guide.value is None else guide_points(self.guide.value, layer)
        if guess is not None and len(guess) == 0:
            notify.error(f"'{self.guide.value.name}' holds no points: click near a few EI centres, or choose none")
            return None

        def work(progress, should_stop):
            import pandas  # noqa: F401  (napari's Points features need it: imported here, not on the GUI thread)

            from napari_ssdpc.calibration import calibrate

            progress(0, 1, "calibrating" if guess is None else f"calibrating from {len(guess)} guide points")
            frame = np.asarray(data if t is None else data[t])
            cal = calibrate(frame, optics, kind=kind, guess=guess)
            progress(1, 1, "calibrated")
            return cal

        return self.runner.start(work, lambda cal: self._done(cal, layer.name), "Calibrate")

    def _points_layers(self, _widget=None):
        from napari.layers import Points

        points = [lyr for lyr in reversed(self.viewer.layers) if isinstance(lyr, Points)]
        return [("none (detect)", None)] + [(lyr.name, lyr) for lyr in points]

    def add_guide_points(self):
        """Add an empty Points layer on the frame, in point-adding mode, and choose it as the guide.

        Returns
        -------
        napari Points layer
        """
        frame = self.image.value
        kwargs = {"name": "EI guide points", "face_color": "yellow", "size": 12}
        if frame is not None:
            kwargs.update(scale=frame.scale[-2:], translate=frame.translate[-2:], units=frame.units[-2:])
        layer = self.viewer.add_points(np.empty((0, 2)), **kwargs)
        layer.mode = "add"
        self.reset_choices()
        self.guide.value = layer
        return layer

    def _done(self, cal, source: str):
        self.calibration = cal
        show_in_turns(self.viewer, calibration_layers(cal, source))
        g = cal.grid
        self.result.value = (
            f"axis (x, y) = ({g.axis_px[0]:.2f}, {g.axis_px[1]:.2f}) px\n"
            f"pitch {g.pitch_px:.3f} px · rotation {g.rotation_deg:+.3f}°\n"
            f"{len(cal.lenslets)} lenslets · lattice rms {cal.residual_px:.3f} px · {cal.kind} frame\n"
            f"{cal.optics.aberrations.summary()}"
            + ("" if cal.rim_defocus_waves is None else f"\nviews' focus (rims): |d| {cal.rim_defocus_waves:.2f} waves")
        )
        return f"calibrated on '{source}'"

    def save(self, path):
        """Write the last calibration.

        Parameters
        ----------
        path : str or Path
            The calibration JSON.
        """
        if self.calibration is None:
            notify.error("nothing to save: run Calibrate first")
            return
        try:
            self.calibration.to_json(path)
        except SsdpcError as e:
            notify.error(e)
