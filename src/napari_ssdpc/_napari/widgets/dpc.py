"""The DPC stack widget: phase (2D) or refractive index (3D) from an LED-array or segmented-condenser
DPC stack layer, with the same phase methods as the light-field frames (docs/dpc.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from magicgui.widgets import ComboBox, FileEdit, FloatSpinBox
from qtpy.QtWidgets import QWidget

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.widgets.choices import LayerChoice, image_layer_choices
from napari_ssdpc._napari.widgets.common import StepWidget, follow_layers, run_buttons, scrolling, show_layer
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.led_dpc import DPC_ALPHA, dpc_settings, reconstruct_dpc
from napari_ssdpc.settings.dpc_optics import DpcOptics

__all__ = ["DpcDock", "DpcWidget"]


class DpcWidget(StepWidget):
    """Reconstruct a DPC stack layer: one image per half-disk pattern (2D) or a z-stack per pattern (3D).

    Parameters
    ----------
    napari_viewer : napari.Viewer
    scrollable : bool
        False inside :class:`DpcDock` (which scrolls).
    """

    def __init__(self, napari_viewer, scrollable: bool = True):
        super().__init__(napari_viewer, scrollable=scrollable)
        self.stack = LayerChoice(
            label="DPC stack",
            choices=image_layer_choices(napari_viewer),
            tooltip="the images, one per pattern in the order of the optics file's patterns_deg "
            "(patterns, y, x), or a z-stack per pattern (patterns, planes, y, x)",
        )
        self.optics = FileEdit(
            label="DPC optics",
            filter="*.yaml *.yml *.json",
            tooltip="the DPC optics file: wavelength, NAs, magnification, camera pixel, patterns, planes (docs/dpc.md)",
        )
        self.method = ComboBox(
            label="method",
            choices=["tikhonov", "tv", "multislice"],
            value="tikhonov",
            tooltip="tikhonov: linear, under a second; tv: total variation with the sign of Δn (seconds); "
            "multislice (z-stacks): tv refined with a multislice model, for strong objects (a minute or more)",
        )
        self.alpha = FloatSpinBox(
            label="α (Tikhonov)",
            min=1e-5,
            max=10.0,
            step=0.005,
            value=DPC_ALPHA,
            tooltip="regularisation relative to the strongest frequency's Σ|H|² per image",
        )
        self.sign = ComboBox(
            label="sign of Δn",
            choices=["any", "auto", "denser", "lighter"],
            value="any",
            tooltip="tv: any for a 2D phase; for a z-stack, denser (cells in water) or auto",
        )
        self.run_button, self.cancel_button, self.status = run_buttons(
            "Reconstruct DPC", "the phase (one image a pattern) or the refractive index (a z-stack a pattern)"
        )
        settings = [self.stack, self.optics, self.method, self.alpha, self.sign]
        self.extend([*settings, self.run_button, self.cancel_button, self.status])
        self.runner = JobRunner("DPC", self.run_button, self.cancel_button, self.status)
        self.run_button.changed.connect(self.run)
        follow_layers(napari_viewer, self)

    def run(self, *_):
        """Reconstruct the chosen stack in the background."""
        layer = self.stack.value
        path = Path(str(self.optics.value))
        if layer is None:
            notify.error("no DPC stack: open the images of the patterns (one layer, patterns first) first")
            return None
        try:
            optics = DpcOptics.from_yaml(path)
            settings = dpc_settings(optics, alpha=float(self.alpha.value), sign=str(self.sign.value))
        except SsdpcError as e:
            notify.error(e)
            return None
        stack, method = np.asarray(layer.data), str(self.method.value)

        def work(progress, should_stop):
            return reconstruct_dpc(stack, optics, method, settings=settings, progress=progress)

        return self.runner.start(work, lambda r: self._done(layer.name, optics, r), "DPC")

    def _done(self, source, optics, r):
        px = r.pixel_um
        if r.phase is not None:
            kwargs = {"name": f"{source} phase", "scale": (px, px), "units": ("µm", "µm"), "colormap": "gray"}
            show_layer(self.viewer, r.phase, kwargs | {"metadata": {"unit": "rad"}})
            return f"{source}: phase {r.phase.min():+.2f} .. {r.phase.max():+.2f} rad ({r.method})"
        ri = optics.medium_index + r.delta_n
        kwargs = {
            "name": f"{source} RI",
            "scale": (r.dz_um, px, px),
            "translate": (float(r.z_um[0]), 0.0, 0.0),
            "units": ("µm", "µm", "µm"),
            "colormap": "magma",
        }
        show_layer(self.viewer, ri, kwargs)
        return f"{source}: RI {ri.min():.4f} .. {ri.max():.4f} on {len(r.z_um)} planes ({r.method})"


class DpcDock(QWidget):
    """The DPC stack widget as the Plugins menu docks it: it scrolls, so that with every dock of the
    plugin open the window still fits a laptop's screen (napari docks a magicgui widget's content
    without its scroll area).

    Parameters
    ----------
    napari_viewer : napari.Viewer

    Attributes
    ----------
    step : DpcWidget
    """

    def __init__(self, napari_viewer):
        super().__init__()
        self.step = DpcWidget(napari_viewer, scrollable=False)
        scrolling(self.step.native, into=self)
