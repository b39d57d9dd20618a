"""One world in micrometres: raw frames and calibration layers beside the reconstructed volumes.

A raw frame lives in sensor pixels and a volume in object-space micrometres; napari refuses to
mix the two ("Inconsistent units across layers"). Each elementary image is the object at the
magnification M_EI, so a sensor pixel spans ``optics.object_pixel_um`` of the object (paper
Eq. 10). Raw frames and the calibration's circles and centres are therefore shown with that
pixel size, in µm, with the frame's centre at the origin, where the volume's optical axis is:
every elementary image appears at the scale of the volume.
"""

from __future__ import annotations

import weakref
from functools import partial

import numpy as np

from napari_ssdpc._napari.turns import later
from napari_ssdpc.settings.optics import Optics

__all__ = [
    "fit_view",
    "follow_optics",
    "follow_results",
    "frame_transform",
    "place_frames",
    "precise_status",
    "scale_bar",
    "show_first_result",
]


def frame_transform(optics: Optics, ndim: int) -> dict:
    """Scale, translation and units of a sensor-pixel layer in object-space micrometres.

    Parameters
    ----------
    optics : Optics
        The instrument (object pixel and sensor size).
    ndim : int
        2 for a (y, x) frame or its overlays, 3 for a (t, y, x) series.

    Returns
    -------
    dict
        ``scale`` (µm per pixel; 1 frame per t step), ``translate`` (µm; the sensor's centre at
        0) and ``units`` ('pixel' for t, 'µm' for y and x), as napari layer keyword arguments.
    """
    s = float(optics.object_pixel_um)
    centre = (-(optics.height_px - 1) / 2 * s, -(optics.width_px - 1) / 2 * s)
    lead = ndim - 2
    return {
        "scale": (1.0,) * lead + (s, s),
        "translate": (0.0,) * lead + centre,
        "units": ("pixel",) * lead + ("µm", "µm"),
    }


def _in_pixels(layer) -> bool:
    """A layer still in sensor pixels (napari's default unit), not one of our results."""
    if layer.metadata.get("ssdpc", {}).get("kind") == "result":
        return False
    units = [str(u) for u in getattr(layer, "units", ())[-2:]]
    return all(u == "pixel" for u in units)


def place_frames(viewer, optics: Optics, again: bool = False) -> int:
    """Show every layer that is still in sensor pixels in object-space µm (see the module notes).

    Parameters
    ----------
    viewer : napari.Viewer
    optics : Optics
        Gives the object pixel and the sensor's centre.
    again : bool
        Also re-place the layers placed before (the optics changed).

    Returns
    -------
    int
        How many layers were placed.
    """
    n = 0
    for layer in list(viewer.layers):
        info = layer.metadata.setdefault("ssdpc", {})
        if not (_in_pixels(layer) or (again and info.get("placed"))) or layer.ndim not in (2, 3):
            continue
        t = frame_transform(optics, layer.ndim)
        layer.scale, layer.translate, layer.units = t["scale"], t["translate"], t["units"]
        info["placed"] = True
        n += 1
    return n


def follow_optics(viewer, session) -> None:
    """Re-place the placed layers whenever the session's optics change.

    Parameters
    ----------
    viewer : napari.Viewer
    session : Session
        Emits ``optics_changed`` with the new optics.
    """
    ref = weakref.ref(viewer)

    def replace(optics):
        v = ref()
        if v is not None and any(lyr.metadata.get("ssdpc", {}).get("placed") for lyr in v.layers):
            place_frames(v, optics, again=True)

    session.optics_changed.connect(replace)


def scale_bar(viewer):
    """The viewer's scale-bar overlay (``canvas.overlays`` since napari 0.9, ``scale_bar`` before).

    Parameters
    ----------
    viewer : napari.Viewer

    Returns
    -------
    The scale-bar overlay model (``visible``, ``unit``, ...).
    """
    canvas = getattr(viewer, "canvas", None)
    overlays = getattr(canvas, "overlays", None)
    return overlays["scale_bar"] if overlays is not None else viewer.scale_bar


def _is_result(layer) -> bool:
    """A reconstruction's layer (a lenslet's PSF stack is not one)."""
    info = layer.metadata.get("ssdpc", {})
    return info.get("kind") == "result" and info.get("quantity") != "psf"


def show_first_result(viewer, layer) -> None:
    """Bring the first result into view: hide the inputs, fit the view to it, switch the scale bar on.

    The inputs are the raw, flat and white frames (placed in µm or marked by this plugin), the
    calibration overlays and the result's source layer; results are left as they are.

    Parameters
    ----------
    viewer : napari.Viewer
    layer : napari Image layer
        A result layer (``metadata['ssdpc']['kind'] == 'result'``), in µm.
    """
    source = layer.metadata["ssdpc"].get("source")
    for lyr in viewer.layers:
        info = lyr.metadata.get("ssdpc", {})
        if not _is_result(lyr) and (
            lyr.name == source or info.get("kind") in ("raw", "calibration") or info.get("placed")
        ):
            lyr.visible = False
    fit_view(viewer, layer)
    bar = scale_bar(viewer)
    bar.visible = True  # every shown layer is in µm: the bar reads µm
    bar.position = "bottom_left"  # napari's notifications pop up over the bottom right


def fit_view(viewer, layer) -> None:
    """Fit the view to ``layer``; to every layer where napari cannot fit one alone (a (z, y, x)
    volume beside a (t, z, y, x) series: napari 0.9 indexes the volume's extent by the viewer's
    axes and fails).

    Parameters
    ----------
    viewer : napari.Viewer
    layer : napari layer
    """
    if layer.ndim == viewer.dims.ndim:
        viewer.fit_to_view(layers=[layer])
    else:
        viewer.reset_view()


def follow_results(viewer=None) -> None:
    """Give the first result that arrives in ``viewer`` the first-result treatment
    (:func:`show_first_result`), however it came: a reconstruction, a streamed series or a file
    opened with File › Open. Installed once per viewer; later results are left as the user set the view.

    Parameters
    ----------
    viewer : napari.Viewer, optional
        Default: napari's current viewer (none: nothing to do).
    """
    if viewer is None:
        import napari

        viewer = napari.current_viewer()  # a reader's: the viewer the file is opened in
    if viewer is None or id(viewer) in _FOLLOWED:
        return
    _FOLLOWED.add(id(viewer))
    weakref.finalize(viewer, _FOLLOWED.discard, id(viewer))
    ref = weakref.ref(viewer)

    def arrived(event):
        v, layer = ref(), event.value
        if v is None or not _is_result(layer):
            return
        precise_status(layer)
        if not any(_is_result(lyr) for lyr in v.layers if lyr is not layer):
            later(partial(show_first_result, v, layer))  # on a turn after napari's adding of the layer

    viewer.layers.events.inserted.connect(arrived)


_FOLLOWED: set[int] = set()  # ids of the viewers whose results are followed


def precise_status(layer) -> None:
    """Show the value under the cursor in the status bar with its quantity's decimals (an RI as
    1.4952, where napari's three significant digits give 1.5).

    Parameters
    ----------
    layer : napari Image layer
        A result layer (``metadata['ssdpc']['quantity']``); left as it is when its quantity has no
        ``decimals``.
    """
    from napari_ssdpc.settings.outputs import QUANTITIES

    quantity = QUANTITIES.get(layer.metadata.get("ssdpc", {}).get("quantity", ""))
    if quantity is None or quantity.decimals is None or getattr(layer, "_ssdpc_status", False):
        return
    napari_status = layer.get_status

    def get_status(position=None, *, view_direction=None, dims_displayed=None, world=False, **kwargs):
        status = napari_status(
            position, view_direction=view_direction, dims_displayed=dims_displayed, world=world, **kwargs
        )
        if position is None:
            return status
        value = layer.get_value(position, view_direction=view_direction, dims_displayed=dims_displayed, world=world)
        if isinstance(value, (float, np.floating)) and np.isfinite(value):
            status["value"] = f"{value:.{quantity.decimals}f}"
            status["coordinates"] = f"{status['coords']}: {status['value']}"
        return status

    layer.get_status = get_status
    layer._ssdpc_status = True
