"""Line profiles: RI (or any image layer) against distance in µm along the lines of a Shapes layer.

Draw a line with the Shapes layer's line tool in the normal xy view, or in an xz / yz view after
changing the displayed axes with napari's dims (e.g. "Transpose" / "Roll dimensions", or
``viewer.dims.order``): a line drawn there lies in the xz (or yz) plane through the current slice,
so axial profiles work the same way. The profile is sampled once per voxel of the line's length
with linear interpolation (``scipy.ndimage.map_coordinates``, order 1) on the layer's data; for a
(t, z, y, x) layer, at the time point on the slider. The plot follows the line while it moves,
and the profiles can be exported to CSV.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from magicgui.widgets import Container, FileEdit, Label, PushButton
from qtpy.QtWidgets import QVBoxLayout, QWidget

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.widgets.choices import LayerChoice, result_layer_choices
from napari_ssdpc._napari.widgets.common import scrolling
from napari_ssdpc._napari.widgets.plot import Deferred, LazyFigure
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import atomic_write


# ============================================================================ sampling
def sample_line(data, start, end, n: int | None = None):
    """Sample ``data`` along the segment ``start`` → ``end`` (data/voxel coordinates, one per axis).

    Leading axes beyond the last three (time) must be constant along the line; they are taken
    at the nearest index. Returns (s, coords, values): the fraction along the line (n,), the
    voxel coordinates (ndim, n) and the linearly interpolated values (n,). ``n`` defaults to one
    sample per voxel of length, plus one.

    Parameters
    ----------
    data : array_like
        The layer's data, (z, y, x) or (t, z, y, x) (or 2D).
    start, end : array_like, (ndim,)
        End points in data (voxel) coordinates.
    n : int, optional
        Number of samples.

    Returns
    -------
    s : ndarray, (n,)
    coords : ndarray, (ndim, n)
    values : ndarray, float32, (n,)
    """
    start, end = np.asarray(start, float), np.asarray(end, float)
    nd = np.ndim(data)
    if start.shape != (nd,) or end.shape != (nd,):
        raise SsdpcError(f"line end points need {nd} coordinates for this layer, got {start.shape[0]}")
    lead = max(nd - 3, 0)
    if lead and not np.allclose(start[:lead], end[:lead]):
        raise SsdpcError("the line changes time point; draw it within one time point")
    if n is None:
        n = max(int(math.ceil(np.linalg.norm(end[lead:] - start[lead:]))) + 1, 2)
    s = np.linspace(0.0, 1.0, int(n))
    coords = start[:, None] + (end - start)[:, None] * s[None, :]
    block = data
    if lead:
        idx = tuple(int(np.clip(round(c), 0, data.shape[i] - 1)) for i, c in enumerate(start[:lead]))
        block = data[idx]
    from scipy import ndimage  # on first use: the dock opens without it

    values = ndimage.map_coordinates(np.asarray(block, np.float32), coords[lead:], order=1, mode="nearest")
    return s, coords, values


def world_line_profile(layer, world_start, world_end, n: int | None = None) -> dict:
    """Profile of image ``layer`` along a segment given in world coordinates (µm for our
    layers): distance (µm), values, world coordinates (n, ndim) and voxel coordinates.

    Parameters
    ----------
    layer : napari Image layer
    world_start, world_end : array_like, (ndim,)
        End points in world coordinates (µm).
    n : int, optional
        Number of samples.

    Returns
    -------
    dict
        ``distance_um`` (n,), ``values`` (n,), ``world`` (n, ndim), ``voxel`` (n, ndim).
    """
    w0, w1 = np.asarray(world_start, float), np.asarray(world_end, float)
    a = np.asarray(layer.world_to_data(w0), float)
    b = np.asarray(layer.world_to_data(w1), float)
    s, coords, values = sample_line(layer.data, a, b, n)
    world = w0[None, :] + s[:, None] * (w1 - w0)[None, :]
    return {"distance_um": s * float(np.linalg.norm(w1 - w0)), "values": values, "world": world, "voxel": coords.T}


def orientation(world_start, world_end, labels) -> str:
    """'xy', 'xz', 'yz', 'axial (z)', 'along x', ... from the axes along which the line runs.

    Parameters
    ----------
    world_start, world_end : array_like
    labels : sequence of str
        Axis labels ('t', 'z', 'y', 'x').

    Returns
    -------
    str
    """
    d = np.abs(np.asarray(world_end, float) - np.asarray(world_start, float))
    moving = [lab for lab, v in zip(labels, d) if v > 1e-9 * max(d.max(), 1.0)]
    order = {"x": 0, "y": 1, "z": 2}
    moving = sorted(moving, key=lambda a: order.get(a, 3))
    if len(moving) == 1:
        return "axial (z)" if moving[0] == "z" else f"along {moving[0]}"
    return "".join(moving) if len(moving) == 2 else "oblique"


# ============================================================================= widget
class ProfileWidget(QWidget):
    """Dock: pick an image layer and a Shapes layer of lines; plots value vs distance (µm)."""

    def __init__(self, napari_viewer):
        super().__init__()
        self.viewer = napari_viewer
        self.image = LayerChoice(
            label="image",
            choices=result_layer_choices(napari_viewer, min_ndim=2, others=True),
            tooltip="layer to sample (default: the newest RI volume; values in its own unit, µm scale)",
        )
        self.lines = LayerChoice(
            label="lines",
            choices=self._shapes,
            tooltip="Shapes layer whose line shapes are profiled (draw with the line tool, in xy or in an xz/yz view)",
        )
        self.new_button = PushButton(
            text="New line layer", tooltip="add a Shapes layer matched to the image's µm scale, in line-drawing mode"
        )
        self.path = FileEdit(mode="w", filter="*.csv")
        self.path.label = "CSV"
        self.path.tooltip = "file for the exported profiles (distance and coordinates in µm)"
        self.export_button = PushButton(text="Export CSV", tooltip="write every profile to the CSV file above")
        self.info = Label(value="")
        self.controls = Container(
            widgets=[self.image, self.lines, self.new_button, self.path, self.export_button, self.info]
        )
        inner = QWidget()
        column = QVBoxLayout(inner)
        column.addWidget(self.controls.native)
        self.plot = LazyFigure(column, (4, 3), 220)  # made with the first profile drawn
        self._axes = None
        self.replot = Deferred(self._plot)
        scrolling(inner, into=self)  # the dock may be short (a laptop screen, other docks open)
        self.profiles: list[dict] = []
        self._connected = []
        ev = napari_viewer.layers.events
        for e in (ev.inserted, ev.removed, ev.reordered):
            e.connect(self._layers_changed)
        napari_viewer.dims.events.current_step.connect(self._dims_changed)
        self.image.changed.connect(self._rewire)
        self.lines.changed.connect(self._rewire)
        self.new_button.changed.connect(self.new_line_layer)
        self.export_button.changed.connect(lambda *_: self.export_csv(self.path.value))
        self._rewire()

    # ------------------------------------------------------------------ layers
    def _shapes(self, _w=None):
        """Shapes layers (not the calibration circles), the top of the layer list first."""
        return [
            (lyr.name, lyr)
            for lyr in reversed(self.viewer.layers)
            if lyr._type_string == "shapes" and lyr.metadata.get("ssdpc", {}).get("kind") != "calibration"
        ]

    def _layers_changed(self, *_):
        try:
            self.controls.reset_choices()
            self._rewire()
        except RuntimeError:  # the dock was closed and its Qt widgets deleted
            pass

    def _rewire(self, *_):
        for emitter, cb in self._connected:
            emitter.disconnect(cb)
        self._connected = []
        for layer, names in ((self.lines.value, ("data", "set_data")), (self.image.value, ("data",))):
            if layer is not None:
                for name in names:
                    emitter = getattr(layer.events, name)
                    emitter.connect(self.update)
                    self._connected.append((emitter, self.update))
        self.update()

    def _dims_changed(self, *_):
        try:
            img = self.image.value
            if img is not None and img.ndim > 3:  # a time series: the profile follows the slider
                self.update()
        except RuntimeError:  # the dock was closed and its Qt widgets deleted
            pass

    def new_line_layer(self, *_):
        """Add a Shapes layer for lines, at the image's µm scale, in line-drawing mode.

        Returns
        -------
        napari Shapes layer
        """
        img = self.image.value
        if img is None:
            return None
        nd = min(img.ndim, 3)
        layer = self.viewer.add_shapes(
            ndim=nd,
            scale=img.scale[-nd:],
            translate=img.translate[-nd:],
            units=img.units[-nd:],  # the image's µm: napari never mixes units, the scale bar keeps µm
            name=f"{img.name} profile lines",
            edge_color="yellow",
            edge_width=float(min(img.scale[-2:])),
        )
        layer.mode = "add_line"
        self.lines.value = layer
        return layer

    # --------------------------------------------------------------- profiles
    def line_segments(self) -> list:
        """(start, end) in world coordinates of every line of the Shapes layer."""
        shapes = self.lines.value
        if shapes is None:
            return []
        point = np.asarray(self.viewer.dims.point, float)
        out = []
        for verts, kind in zip(shapes.data, shapes.shape_type):
            if kind != "line":
                continue
            ends = []
            for v in (verts[0], verts[-1]):
                w = point.copy()
                w[len(w) - shapes.ndim :] = shapes.data_to_world(v)
                ends.append(w)
            out.append(tuple(ends))
        return out

    def compute(self) -> list[dict]:
        """The profiles of every line of the chosen Shapes layer through the chosen image.

        Returns
        -------
        list of dict
            One profile per line (see :func:`world_line_profile`), with its line index and orientation.
        """
        img = self.image.value
        if img is None:
            return []
        labels = list(self.viewer.dims.axis_labels)
        out = []
        for i, (w0, w1) in enumerate(self.line_segments()):
            p = world_line_profile(img, w0, w1)
            p.update(line=i, orientation=orientation(w0, w1, labels), labels=labels)
            out.append(p)
        return out

    def update(self, *_):
        """Recompute the profiles and redraw the plot."""
        try:
            self.profiles = self.compute()
        except SsdpcError as e:
            self.profiles = []
            self.info.value = str(e)
        else:
            self.info.value = f"{len(self.profiles)} line(s)" if self.profiles else "draw a line in the lines layer"
        self.replot()  # drawn on a turn of the event loop of its own, once per burst of events

    @property
    def axes(self):
        """The matplotlib Axes of the profiles (drawn up to date)."""
        self.replot.flush()
        return self._plot_axes()

    def _plot_axes(self):
        if self._axes is None:
            self._axes = self.plot.figure.add_subplot(1, 1, 1)
        return self._axes

    def _plot(self):
        if not self.profiles and not self.plot.made:  # nothing to draw yet: matplotlib can wait
            return
        ax = self._plot_axes()
        ax.clear()
        img = self.image.value
        info = img.metadata.get("ssdpc", {}) if img is not None else {}
        for p in self.profiles:
            ax.plot(p["distance_um"], p["values"], label=f"line {p['line']}: {p['orientation']}")
        ax.set_xlabel("distance (µm)")
        ax.set_ylabel(info.get("unit") or (img.name if img is not None else "value"))
        if self.profiles:
            ax.legend(fontsize=8)
        self.plot.draw()

    def export_csv(self, path):
        """Write all profiles: line, orientation, sample, distance_um, world coordinates (µm; t in
        frames), value. Returns the path, or None (with a notification) when there is nothing to
        write or no file name.

        Parameters
        ----------
        path : str or Path
            The CSV file.

        Returns
        -------
        Path or None
        """
        if not self.profiles:
            notify.error("no profile to export: draw a line in the lines layer first")
            return None
        if not path or Path(path).is_dir():
            notify.error("choose a CSV file name first")
            return None
        labels = self.profiles[0]["labels"]
        try:
            with atomic_write(path) as tmp, open(tmp, "w", newline="") as f:
                w = csv.writer(f)
                coords = [f"{a}_um" if a in ("z", "y", "x") else a for a in labels]
                w.writerow(["line", "orientation", "sample", "distance_um", *coords, "value"])
                for p in self.profiles:
                    for j, (d, xyz, v) in enumerate(zip(p["distance_um"], p["world"], p["values"])):
                        w.writerow(
                            [p["line"], p["orientation"], j, f"{d:.6g}", *(f"{c:.6g}" for c in xyz), repr(float(v))]
                        )
        except SsdpcError as e:
            notify.error(str(e))
            return None
        return path
