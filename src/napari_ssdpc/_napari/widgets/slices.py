"""The Slices widget: xz and yz sections of a reconstruction beside napari's xy view.

The axial resolution of a light-field phase volume is several times coarser than the lateral one,
so a volume is judged on its sections along z. The two sections pass through the viewer's current
point (the z slider and the last clicked position) and follow it; their axes are in µm, drawn to
scale, with the layer's colormap and contrast limits.
"""

from __future__ import annotations

import numpy as np
from magicgui.widgets import Container, Label
from qtpy.QtWidgets import QVBoxLayout, QWidget

from napari_ssdpc._napari.widgets.choices import LayerChoice, result_layer_choices
from napari_ssdpc._napari.widgets.common import MIN_DOCK_HEIGHT_PX, follow_layers, wrap
from napari_ssdpc._napari.widgets.plot import Deferred, LazyFigure

__all__ = ["SlicesWidget", "sections"]


def sections(layer, point) -> dict:
    """The xz and yz sections of a (z, y, x) or (t, z, y, x) image layer through a world point.

    Parameters
    ----------
    layer : napari Image layer
        A result volume, scale in µm.
    point : sequence of float
        World coordinates of the point, µm (and t for a series).

    Returns
    -------
    dict
        ``xz`` (Z, X) and ``yz`` (Z, Y) arrays, the ``extent_xz`` / ``extent_yz`` of each in µm
        (left, right, bottom, top) for matplotlib, and ``at`` = the (z, y, x) voxel they pass through.
    """
    data = layer.data
    idx = np.round(np.asarray(layer.world_to_data(np.asarray(point)[-layer.ndim :]), float)).astype(int)
    idx = np.clip(idx, 0, np.asarray(data.shape) - 1)
    lead = tuple(int(i) for i in idx[:-3])  # the frame of a series
    z, y, x = (int(i) for i in idx[-3:])
    (dz, dy, dx), (z0, y0, x0) = layer.scale[-3:], layer.translate[-3:]
    nz, ny, nx = data.shape[-3:]
    zlim = (z0 + (nz - 0.5) * dz, z0 - 0.5 * dz)  # z grows downward, as in the xz/yz views of napari
    return {  # only the two sections are read (a store's frame stays on disk)
        "xz": np.asarray(data[(*lead, slice(None), y, slice(None))]),
        "yz": np.asarray(data[(*lead, slice(None), slice(None), x)]),
        "extent_xz": (x0 - 0.5 * dx, x0 + (nx - 0.5) * dx, *zlim),
        "extent_yz": (y0 - 0.5 * dy, y0 + (ny - 0.5) * dy, *zlim),
        "at": (z, y, x),
    }


class SlicesWidget(QWidget):
    """xz and yz sections of a reconstruction through the current point, updated as it moves.

    Parameters
    ----------
    napari_viewer : napari.Viewer
    """

    def __init__(self, napari_viewer):
        super().__init__()
        self.viewer = napari_viewer
        self.layer = LayerChoice(
            label="volume",
            choices=result_layer_choices(napari_viewer),
            tooltip="the reconstruction to section (default: the newest RI)",
        )
        self.info = wrap(Label(value=""))
        self.controls = Container(widgets=[self.layer, self.info])
        layout = QVBoxLayout(self)
        layout.addWidget(self.controls.native)
        self.plot = LazyFigure(layout, (4, 5), 2 * MIN_DOCK_HEIGHT_PX)  # made with the first section drawn
        self._images: list = []  # the two sections' images, kept between draws
        self.redraw = Deferred(self.update)  # a burst of layer and slider events draws once
        follow_layers(napari_viewer, self.controls)
        self.layer.changed.connect(self.redraw)
        napari_viewer.dims.events.current_step.connect(self.redraw)
        napari_viewer.mouse_drag_callbacks.append(self._clicked)

    @property
    def figure(self):
        """The matplotlib Figure of the sections."""
        return self.plot.figure

    def _clicked(self, viewer, event):
        """A click in the canvas moves the sections to that position."""
        self._point = tuple(event.position)
        self.redraw()

    def update(self) -> None:
        """Draw the sections of the chosen volume through the current point."""
        layer = self.layer.value
        if layer is None:
            self.info.value = "reconstruct a frame: its xz and yz sections appear here"
            if self.plot.made:
                self.figure.clear()
                self._images = []
                self.plot.draw()
            return
        point = np.array(self.viewer.dims.point, float)
        clicked = getattr(self, "_point", None)
        if clicked is not None and len(clicked) == len(point):
            point[-2:] = np.asarray(clicked)[-2:]  # y, x of the last click; z from the slider
        s = sections(layer, point)
        lo, hi = layer.contrast_limits
        cmap = _mpl_cmap(layer.colormap.name)
        if not self._images:  # the axes are made once: clearing and making them again costs the most
            self.figure.clear()
            for k, (key, label) in enumerate((("xz", "x (µm)"), ("yz", "y (µm)"))):
                ax = self.figure.add_subplot(2, 1, k + 1)
                self._images.append(ax.imshow(s[key], extent=s[f"extent_{key}"], aspect="equal"))
                ax.set_xlabel(label)
                ax.set_ylabel("z (µm)")
                ax.set_title(f"{key} section", fontsize=9)
        for image, key in zip(self._images, ("xz", "yz")):
            image.set_data(s[key])
            image.set_extent(s[f"extent_{key}"])
            image.set_cmap(cmap)
            image.set_clim(lo, hi)
            left, right, bottom, top = s[f"extent_{key}"]
            image.axes.set_xlim(left, right)
            image.axes.set_ylim(bottom, top)
        z, y, x = s["at"]
        dz, dy, dx = layer.scale[-3:]
        z0, y0, x0 = layer.translate[-3:]
        self.info.value = f"through z {z0 + z * dz:.1f} µm, y {y0 + y * dy:.1f} µm, x {x0 + x * dx:.1f} µm"
        self.plot.draw()


def _mpl_cmap(name: str) -> str:
    """matplotlib's name for a napari colormap (napari's 'gray' and most others are the same)."""
    import matplotlib

    return name if name in matplotlib.colormaps else "gray"
