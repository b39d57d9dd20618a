"""Helpers the dock widgets share: layer choices, layer updates, warnings and buttons."""

from __future__ import annotations

import warnings
import weakref
from functools import partial

import numpy as np
from magicgui.widgets import Container, Label, PushButton

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.placement import frame_transform, place_frames
from napari_ssdpc._napari.turns import later
from napari_ssdpc._napari.widgets.session import session_for
from napari_ssdpc.errors import SsdpcError, SsdpcWarning

#: Smallest height of a dock's scrolling content: with every dock open, the window fits 1280 x 800.
MIN_DOCK_HEIGHT_PX = 80

__all__ = [
    "MIN_DOCK_HEIGHT_PX",
    "scrolling",
    "StepWidget",
    "compact",
    "catching_warnings",
    "follow_layers",
    "frame_index",
    "region_um",
    "run_buttons",
    "show_in_turns",
    "show_layer",
    "wrap",
]


def region_um(layer) -> list[float]:
    """The box around every shape of a Shapes layer, in the world's µm (the layers' shared frame).

    Parameters
    ----------
    layer : napari.layers.Shapes
        Rectangles, polygons, ... drawn over the views or the RI layers (last two axes y, x).

    Returns
    -------
    list of float
        [x_min, x_max, y_min, y_max], µm.
    """
    if not len(layer.data):
        raise SsdpcError(f"the layer '{layer.name}' holds no shape: draw the region (a rectangle) in it first")
    scale, shift = np.asarray(layer.scale)[-2:], np.asarray(layer.translate)[-2:]
    yx = np.concatenate([np.asarray(d)[:, -2:] for d in layer.data]) * scale + shift
    return [float(yx[:, 1].min()), float(yx[:, 1].max()), float(yx[:, 0].min()), float(yx[:, 0].max())]


def follow_layers(viewer, container: Container):
    """Refresh the container's layer choices when layers come, go, move or are renamed (also when
    the widget is used outside a dock); a closed widget is left alone.

    Parameters
    ----------
    viewer : napari.Viewer
    container : magicgui Container
    """
    ref = weakref.ref(container)

    def refresh(*_):
        w = ref()
        if w is not None:
            try:
                w.reset_choices()
            except RuntimeError:  # the Qt widget was deleted with its dock
                pass

    ev = viewer.layers.events
    for e in (ev.inserted, ev.removed, ev.reordered):
        e.connect(refresh)
    ev.inserted.connect(lambda event: event.value.events.name.connect(refresh))


def frame_index(viewer, layer) -> int | None:
    """Time index of ``layer`` (t, y, x) at the viewer's current position; None for a 2D frame.

    Parameters
    ----------
    viewer : napari.Viewer
    layer : napari Image layer

    Returns
    -------
    int or None
    """
    if layer.ndim < 3:
        return None
    pos = layer.world_to_data(viewer.dims.point)
    return int(np.clip(round(float(pos[0])), 0, layer.data.shape[0] - 1))


def show_layer(viewer, data, kwargs: dict, layer_type: str = "image"):
    """Add a layer, or update the one of the same name in place (same object, same position).

    A layer whose dimensionality changes (a frame, then a series) is replaced at its position. All
    layers share one world in µm: frames still in sensor pixels are placed first, and a layer in
    sensor pixels (a calibration's circles and centres) comes in placed (:mod:`..placement`).

    Parameters
    ----------
    viewer : napari.Viewer
    data : array_like or list
        The layer data.
    kwargs : dict
        napari layer keyword arguments, with ``name``.
    layer_type : str
        'image', 'shapes' or 'points'.

    Returns
    -------
    napari layer
    """
    optics = session_for(viewer).optics
    place_frames(viewer, optics)
    if kwargs.get("metadata", {}).get("ssdpc", {}).get("kind") != "result" and "units" not in kwargs:
        kwargs = {**kwargs, **frame_transform(optics, np.ndim(data) if layer_type == "image" else 2)}
        kwargs["metadata"] = {**kwargs.get("metadata", {})}
        kwargs["metadata"]["ssdpc"] = {**kwargs["metadata"].get("ssdpc", {}), "placed": True}
    name = kwargs["name"]
    if name in viewer.layers:
        old = viewer.layers[name]
        if layer_type == "image" and old._type_string == "image" and old.ndim == np.ndim(data):
            old.data = data
            # the display choices (colormap, rendering, ...) stay as the user left them
            for key in ("scale", "translate", "metadata", "contrast_limits", "axis_labels", "units"):
                if key in kwargs:
                    setattr(old, key, kwargs[key])
            return old
        index = viewer.layers.index(old)
        viewer.layers.remove(old)
        new = getattr(viewer, f"add_{layer_type}")(data, **kwargs)
        viewer.layers.move(viewer.layers.index(new), index)
        return new
    return getattr(viewer, f"add_{layer_type}")(data, **kwargs)


def show_in_turns(viewer, layers, key=None) -> None:
    """Show layers one per turn of the event loop (:func:`..turns.later`): napari adding several
    layers in one event (a calibration's circles, labelled centres and deviations; a result's
    quantities) stalls the GUI for their sum; between turns it draws and answers.

    Parameters
    ----------
    viewer : napari.Viewer
    layers : list of (data, kwargs, type)
        As :func:`show_layer` takes them.
    key : hashable, optional
        A layer shown again under the same key (a store's newer reading) replaces the one still
        waiting.
    """
    for data, kwargs, kind in layers:
        later(partial(show_layer, viewer, data, kwargs, kind), key=None if key is None else (key, kwargs["name"]))


def catching_warnings(fn, *args, **kwargs):
    """Call fn; show each SsdpcWarning it raises as a napari warning notification.

    Parameters
    ----------
    fn : callable
    *args, **kwargs
        Passed to ``fn``.

    Returns
    -------
    What ``fn`` returns.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SsdpcWarning)
        out = fn(*args, **kwargs)
    for w in caught:
        if issubclass(w.category, SsdpcWarning):
            notify.warning(str(w.message))
    return out


def run_buttons(run_text: str, run_tip: str):
    """A Run button, a Cancel button and a wrapping status line.

    Parameters
    ----------
    run_text : str
    run_tip : str

    Returns
    -------
    run, cancel : PushButton
    status : Label
    """
    run = PushButton(text=run_text, tooltip=run_tip)
    cancel = PushButton(text="Cancel", tooltip="stop the running job within one iteration")
    status = Label(value="")
    wrap(status)
    return run, cancel, status


def wrap(label: Label) -> Label:
    """Let a label's text wrap, so a long message never widens its dock.

    Parameters
    ----------
    label : magicgui Label

    Returns
    -------
    Label
        The same label.
    """
    from qtpy.QtWidgets import QSizePolicy

    label.native.setWordWrap(True)
    # its long lines never set the dock's width: it takes the width there is and wraps
    label.native.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
    return label


def scrolling(widget, into=None):
    """``widget`` in a scroll area that can shrink to :data:`MIN_DOCK_HEIGHT_PX`: a dock scrolls
    instead of making the window taller than the screen (a laptop, other docks open).

    Parameters
    ----------
    widget : QWidget
        The content.
    into : QWidget, optional
        Also make the scroll area the whole of this widget (its only child, no margins).

    Returns
    -------
    QScrollArea
    """
    from qtpy.QtWidgets import QScrollArea, QVBoxLayout

    area = QScrollArea()
    area.setWidgetResizable(True)
    area.setWidget(widget)
    area.setMinimumHeight(MIN_DOCK_HEIGHT_PX)
    if into is not None:
        layout = QVBoxLayout(into)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(area)
    return area


def compact(container: Container) -> Container:
    """Let a scrollable container shrink to :data:`MIN_DOCK_HEIGHT_PX` (it scrolls instead of
    making the window taller).

    Parameters
    ----------
    container : magicgui Container
        Made with ``scrollable=True``.

    Returns
    -------
    Container
        The same container.
    """
    container.root_native_widget.setMinimumHeight(MIN_DOCK_HEIGHT_PX)  # the scroll area around ``native``
    return container


class StepWidget(Container):
    """A step of the workflow: a scrolling container that works on the viewer's shared session.

    Parameters
    ----------
    napari_viewer : napari.Viewer
        The viewer (or napari's proxy of it).
    role : str, optional
        The session's slot for this kind of step ('operators_widget', 'reconstruct_widget'):
        when the dock and a separate widget of the same kind are open, the one edited last counts.
    scrollable : bool
        False for a step shown inside another (that one scrolls).
    """

    def __init__(self, napari_viewer, role: str | None = None, scrollable: bool = True):
        super().__init__(labels=True, scrollable=scrollable)
        compact(self)
        self.viewer = napari_viewer
        self.session = session_for(napari_viewer)
        if role is not None:
            self.session.use(role, self)
            self.changed.connect(lambda *_: self.session.use(role, self))
