"""How a result and a calibration look in napari: one layer per quantity, styled from the
registry of outputs; a calibration's EI circles, centres and deviations.

The readers and the widgets both build their layers here, so a file opened from disk looks
exactly like a freshly computed result or calibration.
"""

from __future__ import annotations

import numpy as np

from napari_ssdpc.settings.outputs import QUANTITIES, display

__all__ = [
    "PSF_STYLE",
    "SPIKE_RATIO",
    "axial_fwhm_um",
    "calibration_layers",
    "is_map",
    "object_extremes",
    "resolution_text",
    "result_arrays",
    "result_layer",
]

#: A voxel this many times above the level of its 3 x 3 surroundings is a spike, not an object's peak.
SPIKE_RATIO = 1.5
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


def _optics(info: dict):
    """The Optics in a result's metadata, or None."""
    if not info.get("optics"):
        return None
    from napari_ssdpc.errors import SsdpcError
    from napari_ssdpc.settings.optics import Optics

    try:
        return Optics.from_dict(info["optics"])
    except (SsdpcError, TypeError, ValueError):
        return None


def axial_fwhm_um(optics) -> float:
    """The axial resolution to expect from a first-order reconstruction at these optics, µm.

    The FWHM along z of a small object: R_z (paper Eq. 13, the f_fl variant that reproduces the
    paper's 20.6 µm) scaled by the parallax of the lenslets that straddle the source edge
    (:func:`napari_ssdpc.physics.design.design`, ``expected_axial_fwhm_um``).

    Parameters
    ----------
    optics : Optics

    Returns
    -------
    float
        µm; inf when no lenslet straddles the source edge (no phase contrast along z).
    """
    from napari_ssdpc.physics.design import design

    return float(design(optics)["expected_axial_fwhm_um"])


def resolution_text(fwhm_um: float) -> str:
    """One line on the axial resolution shown with a result (status line, layer metadata).

    Parameters
    ----------
    fwhm_um : float
        Expected axial FWHM, µm (:func:`axial_fwhm_um`).

    Returns
    -------
    str
    """
    if not np.isfinite(fwhm_um):
        return "no axial resolution at this condenser NA (no lenslet straddles the source edge)"
    return f"axial resolution ≈ {fwhm_um:.0f} µm (expected FWHM along z): features closer in z merge"


def object_extremes(dev, voxel_um, origin_um, field_radius_um: float | None = None) -> tuple[float, float]:
    """How far the objects reach below and above the centre of the colormap (the medium for RI).

    The largest negative and positive deviation inside the field of view, leaving out lone spikes: a voxel counts when
    it rises at most :data:`SPIKE_RATIO` times above the level of its surroundings (the grey-scale
    opening of |deviation| over 3 x 3 voxels of its plane, dilated over the same window). An
    object's peak stays a few % above that level, a single hot voxel stands far above it. A
    percentile over the whole volume would instead follow the volume's size: a small object fills
    under 1 % of it, and its core would be clipped (the bead sample's Δn −0.017 drawn at ±0.011).

    Parameters
    ----------
    dev : ndarray, (z, y, x) or (y, x)
        Deviation from the centre of the colormap (Δn = RI − medium, or a signed quantity).
    voxel_um, origin_um : sequence of float
        (.., dy, dx) voxel size and (.., y0, x0) position of voxel 0, µm (the optical axis at 0).
    field_radius_um : float, optional
        Radius of the field of view about the optical axis, µm; None: the whole plane.

    Returns
    -------
    below, above : float
        The deepest negative and the highest positive deviation, as magnitudes ≥ 0: contrast limits
        centre ± max(below, above) span every object; the larger one is the sign that dominates.
    """
    from scipy import ndimage

    dev = np.asarray(dev, np.float32)
    a = np.abs(dev)
    if field_radius_um is not None:
        y = origin_um[-2] + voxel_um[-2] * np.arange(a.shape[-2])
        x = origin_um[-1] + voxel_um[-1] * np.arange(a.shape[-1])
        inside = y[:, None] ** 2 + x[None, :] ** 2 <= field_radius_um**2
        if inside.any():
            a = a * inside
    size = (1,) * (a.ndim - 2) + (3, 3)
    level = ndimage.grey_dilation(ndimage.grey_opening(a, size=size), size=size)  # the surroundings' level
    kept = dev[(a > 0) & (a <= SPIKE_RATIO * level)]  # a lone hot voxel stands far above it, a peak does not
    if kept.size == 0:
        return 1e-6, 1e-6
    return max(-float(kept.min()), 0.0), max(float(kept.max()), 0.0)


def result_layer(data, quantity: str, voxel_um, origin_um, *, name: str, info: dict | None = None, limits: bool = True):
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
    limits : bool
        Give the contrast limits and rendering (which read the data: its first frame); False for a
        layer that keeps its own (no data read).

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
    voxel = tuple(float(v) for v in voxel_um)[-spatial:]
    origin = tuple(float(v) for v in origin_um)[-spatial:]
    shown = _display(data[0] if time else data, quantity, centred, voxel, origin, info) if limits else {}
    info.update(kind="result", quantity=quantity, unit=unit, voxel_um=list(voxel), origin_um=list(origin))
    if "axial_fwhm_um" not in info and quantity != "psf" and (optics := _optics(info)) is not None:
        info["axial_fwhm_um"] = axial_fwhm_um(optics)  # shown with the result: z is several times coarser
    kwargs = {
        "name": name if name.endswith(suffix) else f"{name} {suffix}",
        "scale": ((1.0,) if time else ()) + voxel,
        "translate": ((0.0,) if time else ()) + origin,
        "axis_labels": (("t",) if time else ()) + ("z", "y", "x")[-spatial:],
        "units": (("pixel",) if time else ()) + ("µm",) * spatial,
        "colormap": cmap,
        **shown,
        "metadata": {"ssdpc": info},
    }
    return (data, kwargs, "image")


def _display(frame, quantity: str, centred: bool, voxel, origin, info: dict) -> dict:
    """Contrast limits and 3D rendering of one frame: centred on the medium (RI) or 0, spanning the
    objects in the field (:func:`object_extremes`); else the 0.1-99.9 percentiles."""
    block = np.asarray(frame, np.float32)
    first = block[np.isfinite(block)]  # a series still being written: its later frames are NaN
    if first.size == 0:
        first = np.zeros(1, np.float32)
    centre = 0.0
    if quantity == "ri":
        centre = float(info.get("medium_index") or (info.get("optics") or {}).get("medium_index") or np.median(first))
    rendering = "mip"
    if centred:
        dev = np.nan_to_num(block - centre)
        optics = _optics(info)
        below, above = object_extremes(dev, voxel, origin, None if optics is None else optics.fov_um / 2)
        a = max(below, above) or 1e-6
        lims = [centre - a, centre + a]
        if below > above:
            rendering = "minip"
    else:
        lo, hi = (float(v) for v in np.percentile(first, [0.1, 99.9]))
        lims = [lo, hi if hi > lo else lo + 1e-6]
    return {"contrast_limits": lims, "rendering": rendering}


def calibration_layers(cal, name: str) -> list:
    """Layer data of a calibration: the EI circles (a Points layer drawn as circles of the EI's
    diameter; green: at least half inside the pupil, orange: clipped edge lenslets; its metadata's
    ``role`` is 'EI circles'), Points of the EI centres labelled (row, col) plus the
    optical axis, and Vectors of each measured centre's deviation from the lattice (magnified by
    ``metadata['ssdpc']['deviation_gain']``). All carry the calibration dict in
    ``metadata['ssdpc']['calibration']``.

    Parameters
    ----------
    cal : Calibration
    name : str
        Stem of the layer names.

    Returns
    -------
    list of (data, kwargs, type)
    """
    d = cal.to_dict()
    meta = {"ssdpc": {"kind": "calibration", "calibration": d}}
    r = float(cal.ei_radius_px)
    c = np.asarray(cal.centres_px, float)  # (K, 2) x, y
    edge = ["lime" if ln.fraction >= 0.5 else "orange" for ln in cal.lenslets]
    circles = (  # points drawn as rings of the EI's diameter: a Shapes layer of ellipses took 0.5-0.8 s to draw
        c[:, ::-1],
        {
            "name": f"{name} EI circles",
            "symbol": "disc",
            "size": 2 * r,
            "face_color": "transparent",
            "border_color": edge,
            "border_width": 2,
            "border_width_is_relative": False,
            "metadata": {"ssdpc": {**meta["ssdpc"], "role": "EI circles"}},
        },
        "points",
    )
    ax, ay = cal.grid.axis_px
    pts = np.vstack([c[:, ::-1], [[ay, ax]]])
    labels = [f"({ln.row}, {ln.col})" for ln in cal.lenslets] + ["axis"]
    points = (
        pts,
        {
            "name": f"{name} EI centres",
            "features": {"label": labels},
            "text": {
                "string": "{label}",
                "color": "magenta",
                "size": 10,
                "anchor": "center",
                "translation": [-0.45 * r, 0.0],
            },
            "symbol": ["disc"] * len(c) + ["cross"],
            "size": [8] * len(c) + [30],
            "face_color": ["lime"] * len(c) + ["red"],
            "metadata": meta,
        },
        "points",
    )
    start, arrow, gain = cal.deviation_arrows()
    vectors = (
        np.stack([start[:, ::-1], arrow[:, ::-1]], axis=1).reshape(-1, 2, 2),  # (M, [position, arrow], (y, x))
        {
            "name": f"{name} EI deviations",  # magnified: see the metadata
            "edge_color": "cyan",
            "edge_width": 2,
            "vector_style": "arrow",
            "metadata": {"ssdpc": {**meta["ssdpc"], "deviation_gain": gain}},
        },
        "vectors",
    )
    return [circles, points, vectors]


def result_arrays(res, wanted) -> dict:
    """The wanted quantities of a core Result, channels split ('dpc_ud', 'stack_up', ...).

    Parameters
    ----------
    res : Result
        One reconstructed frame.
    wanted : iterable of str
        Registry names ('ri', 'opd_nm', 'dpc', ...).

    Returns
    -------
    dict
        {layer key: (z, y, x) volume or (y, x) map}; quantities the result does not hold are left out.
    """
    out = {}
    for name in wanted:
        q = QUANTITIES[name]
        value = q.get(res)
        if value is None or (q.kind == "channels" and not value):
            continue
        if q.kind == "channels":
            out.update({k: np.asarray(value[c]) for c, k in zip(q.channels, q.channel_keys())})
        else:
            out[name] = np.asarray(value)
    return out
