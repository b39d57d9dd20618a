"""How a result looks in napari: one layer per quantity, styled from the registry of outputs.

The readers and the widgets both build their result layers here, so a file opened from disk
looks exactly like a freshly computed result.
"""

from __future__ import annotations

import numpy as np

from napari_ssdpc.settings.outputs import display

__all__ = ["PSF_STYLE", "is_map", "result_layer"]

#: Display of a lenslet's PSF stack (Operators widget): not a reconstruction output.
PSF_STYLE = ("PSF", "magma", "fraction of one lenslet's light per pixel", False)


def is_map(key: str) -> bool:
    """A 2D quantity (projected phase, OPD, dry mass): (y, x) per frame.

    Parameters
    ----------
    key : str
        Registry or channel key.

    Returns
    -------
    bool
    """
    q, _ = display(key)
    return q is not None and q.kind == "map"


def result_layer(data, quantity: str, voxel_um, origin_um, *, name: str, info: dict | None = None):
    """Layer data tuple of a result, styled from the registry of output quantities.

    Parameters
    ----------
    data : array_like
        (z, y, x) volume or (y, x) map, or a series of them with a leading t axis.
    quantity : str
        Registry key or channel key ('ri', 'opd_nm', 'dpc_ud', ...), or 'psf'.
    voxel_um, origin_um : sequence of float
        (z, y, x) voxel size and position of voxel 0, µm (a map uses the last two).
    name : str
        Layer name stem; the quantity's label is appended.
    info : dict, optional
        Metadata kept under ``metadata['ssdpc']`` (settings, optics, source).

    Returns
    -------
    tuple
        napari's (data, kwargs, 'image'): scale in µm, axis labels, units, colormap, contrast
        limits centred on the medium index (RI) or on 0 for signed quantities, and a 3D rendering
        that shows the dominant sign.
    """
    info = dict(info or {})
    q, suffix = display(quantity)
    suffix, cmap, unit, centred = (
        PSF_STYLE
        if quantity == "psf"
        else (suffix, "gray", "", False)
        if q is None
        else (suffix, q.colormap, q.unit or q.description, q.centred)
    )
    spatial = 2 if is_map(quantity) else 3  # a 2D map (OPD, dry mass) or a volume
    time = data.ndim == spatial + 1
    first = np.asarray(data[0] if time else data, np.float32)
    first = first[np.isfinite(first)]  # a series still being written: its later frames are NaN
    if first.size == 0:
        first = np.zeros(1, np.float32)
    centre = 0.0
    if quantity == "ri":
        centre = float(info.get("medium_index") or (info.get("optics") or {}).get("medium_index") or np.median(first))
    rendering = "mip"
    if centred:
        dev = first - centre
        a = float(np.percentile(np.abs(dev), 99.9)) or float(np.abs(dev).max()) or 1e-6
        lims = [centre - a, centre + a]
        if -float(dev.min()) > float(dev.max()):
            rendering = "minip"
    else:
        lo, hi = (float(v) for v in np.percentile(first, [0.1, 99.9]))
        lims = [lo, hi if hi > lo else lo + 1e-6]
    voxel = tuple(float(v) for v in voxel_um)[-spatial:]
    origin = tuple(float(v) for v in origin_um)[-spatial:]
    info.update(kind="result", quantity=quantity, unit=unit, voxel_um=list(voxel), origin_um=list(origin))
    kwargs = {
        "name": name if name.endswith(suffix) else f"{name} {suffix}",
        "scale": ((1.0,) if time else ()) + voxel,
        "translate": ((0.0,) if time else ()) + origin,
        "axis_labels": (("t",) if time else ()) + ("z", "y", "x")[-spatial:],
        "units": (("pixel",) if time else ()) + ("µm",) * spatial,
        "colormap": cmap,
        "contrast_limits": lims,
        "rendering": rendering,
        "metadata": {"ssdpc": info},
    }
    return (data, kwargs, "image")
