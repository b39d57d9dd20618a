"""napari readers: raw light-field frames, calibration JSON, reconstruction outputs.

Each ``get_*_reader(path)`` looks inside the file and returns None when it is not its own, so
napari can try another reader. The layers are built as the widgets build them
(``layers.calibration_layers``, ``layers.result_layer``), so a file opened from disk looks exactly
like a freshly computed result.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from napari_ssdpc._napari.layers import calibration_layers, is_map, result_layer
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.frames import TiffInfo, tiff_info
from napari_ssdpc.settings.outputs import QUANTITIES

RESULT_FORMAT = "napari-ssdpc-result"
RESULT_VERSION = 1
MIN_FRAME_PX = 32  # smaller images are not light-field frames
MAX_JSON_BYTES = 50_000_000


def _stem(p: Path) -> str:
    """File name without its data suffix (.ome.tif, .tif, .zarr, .json, ...)."""
    name = p.name
    for ext in (
        ".ssdpc.ome.tiff",
        ".ssdpc.ome.tif",
        ".ssdpc.zarr",
        ".ome.tiff",
        ".ome.tif",
        ".tiff",
        ".tif",
        ".zarr",
        ".json",
    ):
        if name.lower().endswith(ext):
            return name[: -len(ext)]
    return p.stem


def _path(path):
    """A single file path, or None (napari may pass a list of paths)."""
    if isinstance(path, (list, tuple)):
        return None
    return Path(path) if isinstance(path, (str, Path)) else None


# =========================================================================== raw frames
def get_raw_reader(path):
    """Reader for raw light-field frames: a 2D frame or a (t, y, x) series in a TIFF/OME-TIFF.

    Parameters
    ----------
    path : str or list of str

    Returns
    -------
    callable or None
        :func:`read_raw`, or None when the file is not a raw frame or series.
    """
    p = _path(path)
    if p is None or p.suffix.lower() not in (".tif", ".tiff") or not p.is_file():
        return None
    try:
        ok = _is_raw_tiff(p)
    except Exception:  # not a TIFF tifffile can parse: not ours
        return None
    return read_raw if ok else None


def _is_raw_tiff(p: Path) -> bool:
    info = tiff_info(p)
    if _our_description(info) is not None:  # a reconstruction: the result reader's job
        return False
    dims = [(a, n) for a, n in zip(info.axes, info.shape) if n > 1]
    if any(a in "SC" for a, _ in dims):  # RGB or multi-channel: a foreign image
        return False
    if len(dims) not in (2, 3) or info.dtype.kind not in "uif":
        return False
    if min(n for _, n in dims[-2:]) < MIN_FRAME_PX:
        return False
    if len(dims) == 3 and dims[0][0] == "Z" and "PhysicalSizeZ" in (info.ome or {}).get("Pixels", {}):
        return False  # a calibrated z-stack: a volume, not a series
    return info.complete


def open_lazy(path, squeeze: bool = True):
    """The data without reading the pixels: a numpy memmap where the file allows it (an
    uncompressed TIFF), else a dask array over tifffile's zarr store. ``squeeze``: drop
    length-1 axes.

    Parameters
    ----------
    path : str or Path
    squeeze : bool

    Returns
    -------
    numpy.memmap or dask.array.Array
    """
    import tifffile

    try:
        data = tifffile.memmap(path, mode="r")
    except Exception:  # compressed or tiled: go through the zarr store
        import dask.array as da
        import zarr

        data = da.from_zarr(zarr.open(tifffile.imread(path, aszarr=True), mode="r"))
    shape = tuple(n for n in data.shape if n > 1)
    return data.reshape(shape) if squeeze and shape != data.shape else data


def read_raw(path):
    """The raw frame or (t, y, x) series of a TIFF as one lazy image layer.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of (data, kwargs, 'image')
    """
    p = Path(path)
    data = open_lazy(p)
    first = np.asarray(data[0] if data.ndim == 3 else data)
    lo, hi = np.percentile(first[::4, ::4], [1, 99.9])
    kwargs = {
        "name": _stem(p),
        "contrast_limits": [float(lo), float(max(hi, lo + 1))],
        "metadata": {"ssdpc": {"kind": "raw", "path": str(p)}},
    }
    if data.ndim == 3:
        kwargs["axis_labels"] = ("t", "y", "x")
    return [(data, kwargs, "image")]


# ========================================================================== calibration
def get_calibration_reader(path):
    """Reader for our calibration JSON (``format: napari-ssdpc-calibration``).

    Parameters
    ----------
    path : str or list of str

    Returns
    -------
    callable or None
    """
    p = _path(path)
    if p is None or p.suffix.lower() != ".json" or not p.is_file() or p.stat().st_size > MAX_JSON_BYTES:
        return None
    from napari_ssdpc.calibration.result import CALIBRATION_FORMAT

    try:
        d = json.loads(p.read_text())
    except (ValueError, UnicodeDecodeError, OSError, RecursionError):  # not JSON, or nested too deep
        return None
    if not isinstance(d, dict) or d.get("format") != CALIBRATION_FORMAT:
        return None
    return read_calibration


def read_calibration(path):
    """A calibration JSON as its EI-circles and centres layers.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of layer data tuples
    """
    from napari_ssdpc.calibration import Calibration

    p = Path(path)
    cal = Calibration.from_json(p)
    return calibration_layers(cal, _stem(p))


# ======================================================================= reconstructions
# Our outputs carry a JSON description: in the OME-XML Description of an OME-TIFF, in the
# ``napari_ssdpc`` attribute of an OME-Zarr image group. The writer of this plugin and the
# ``ssdpc reconstruct`` command both write ``software: "napari-ssdpc <version>"``; an OME-Zarr
# store holds one image group per quantity ("ri", "phase", "dpc", ...).
CHANNELS = {q.name: list(q.channel_keys()) for q in QUANTITIES.values() if q.kind == "channels"}
_WORDS = [
    ("difference", "delta_n"),
    ("refractive", "ri"),
    ("phase", "phase"),
    ("absorption", "absorption"),
    ("dpc", "dpc"),
    ("stack", "stacks"),
]


def get_result_reader(path):
    """Reader for our reconstruction outputs: OME-TIFF (.ome.tif) or OME-Zarr (.zarr folder).

    Parameters
    ----------
    path : str or list of str

    Returns
    -------
    callable or None
    """
    p = _path(path)
    if p is None or not p.exists():
        return None
    try:
        if p.is_dir() and p.suffix.lower() == ".zarr":
            ours = bool(zarr_images(p))
        else:
            ours = p.is_file() and p.suffix.lower() in (".tif", ".tiff") and _our_description(tiff_info(p)) is not None
    except Exception:  # unreadable or foreign: not ours
        return None
    if ours:
        from napari_ssdpc._napari.placement import follow_results

        follow_results()  # the first result opened is brought into view with a scale bar in µm
    return read_result if ours else None


def _is_ours(d) -> bool:
    return isinstance(d, dict) and (
        d.get("format") == RESULT_FORMAT or str(d.get("software", "")).startswith("napari-ssdpc")
    )


def _our_description(info: TiffInfo):
    """Our JSON description from an OME-TIFF's OME-XML, or None."""
    desc = (info.ome or {}).get("Description")
    try:
        d = json.loads(desc) if isinstance(desc, str) else None
    except ValueError:
        return None
    return d if _is_ours(d) else None


def zarr_images(p: Path) -> list:
    """[(name, group)] of our OME-NGFF image groups: the root itself or its child groups.

    Parameters
    ----------
    p : Path
        The ``.zarr`` store.

    Returns
    -------
    list of (str, zarr.Group)
    """
    import zarr

    root = zarr.open_group(str(p), mode="r")
    groups = [(_stem(p), root)] + [(k, root[k]) for k in sorted(root.group_keys())]
    return [(k, g) for k, g in groups if "multiscales" in g.attrs and _is_ours(dict(g.attrs).get("napari_ssdpc"))]


def quantity_key(desc: dict, hint: str = "") -> str:
    """Our quantity key ('ri', 'phase', 'dpc', ...) from a description, the image-group name or
    the file-name suffix (OUT_phase.ome.tif), or the description's wording.

    Parameters
    ----------
    desc : dict
        Our description of the image.
    hint : str
        Group name or file-name suffix.

    Returns
    -------
    str
    """
    for q in (desc.get("quantity"), hint):
        if q in QUANTITIES or q in CHANNELS:
            return q
    text = str(desc.get("quantity", "")).lower()
    return next((key for word, key in _WORDS if word in text), "ri")


def read_result(path, limits: bool = True):
    """Our OME-TIFF or OME-Zarr result as styled layers (lazy where the file allows).

    Parameters
    ----------
    path : str or Path
        ``.ome.tif`` or ``.zarr``.
    limits : bool
        Give display limits (reading the first frame); False for layers that keep theirs (a store
        shown again as it grows: nothing is read but the metadata).

    Returns
    -------
    list of (data, kwargs, 'image')
    """
    p = Path(path)
    try:
        return _read_zarr(p, limits) if p.is_dir() else _read_tiff(p, limits)
    except SsdpcError:
        raise
    except Exception as e:  # our format with damaged metadata: zarr, tifffile and JSON raise many types
        raise SsdpcError(
            f"{p}: a napari-ssdpc result whose metadata is damaged ({type(e).__name__}); reconstruct it again"
        ) from None


def _read_tiff(p: Path, limits: bool = True):
    info = tiff_info(p)
    desc, pixels = _our_description(info), (info.ome or {}).get("Pixels", {})
    data = open_lazy(p, squeeze=False)
    axes = info.axes.replace("Q", "").replace("I", "T")
    voxel = tuple(float(pixels.get(f"PhysicalSize{a}", 1.0)) for a in "ZYX")
    stem = _stem(p)
    hint = stem.rsplit("_", 1)[-1] if "_" in stem else ""
    q = quantity_key(desc, hint)
    if "Z" not in axes and axes.endswith("YX") and not is_map(q):  # one plane (--z 5 5): tifffile drops Z
        data, axes = data[..., np.newaxis, :, :], axes[:-2] + "ZYX"
    if q == hint or (hint == "n" and q == "delta_n"):  # OUT_phase.ome.tif, OUT_delta_n.ome.tif
        stem = stem[: -len(q) - 1]
    desc = {"name": stem, **desc, "quantity": q}
    return _result_layers(data, axes, desc, voxel, limits)


def _read_zarr(p: Path, limits: bool = True):
    import dask.array as da

    layers = []
    from napari_ssdpc.io.store import mask_incomplete

    for key, g in zarr_images(p):
        desc = dict(g.attrs["napari_ssdpc"])
        ms = g.attrs["multiscales"][0]
        ds = ms["datasets"][0]
        axes = "".join(a["name"] for a in ms["axes"]).upper()
        data = da.from_zarr(g[ds["path"]])
        if axes.startswith("T"):  # a series: frames not marked done are NaN, never half a frame
            data = mask_incomplete(data, p)
        tr = {t["type"]: t[t["type"]] for t in ds["coordinateTransformations"]}
        voxel = tuple(float(s) for a, s in zip(axes, tr["scale"]) if a in "ZYX")
        if "translation" in tr and "origin_um" not in desc:
            desc["origin_um"] = [float(s) for a, s in zip(axes, tr["translation"]) if a in "ZYX"]
        desc = {"name": _stem(p), **desc, "quantity": quantity_key(desc, key)}
        layers += _result_layers(data, axes, desc, voxel, limits)
    return layers


def _origin(desc: dict, shape_zyx, voxel) -> tuple:
    """The (z, y, x) µm position of voxel 0: stored, else z_min of the settings and the view
    centred on the optical axis (the pipeline's grid)."""
    if desc.get("origin_um") is not None:
        return tuple(float(v) for v in desc["origin_um"])
    z0 = desc.get("z_um", [None])[0]
    if z0 is None:
        z0 = (desc.get("settings") or {}).get("z_min_um", -(shape_zyx[0] - 1) / 2 * voxel[0])
    return (float(z0),) + tuple(-(n - 1) / 2 * d for n, d in zip(shape_zyx[1:], voxel[1:]))


def _result_layers(data, axes: str, desc: dict, voxel, limits: bool = True):
    """Split channels if any, keep (T)ZYX, and style each quantity."""
    axes = axes.upper()
    if not (len(voxel) == 3 and all(math.isfinite(v) and v > 0 for v in voxel)):
        raise SsdpcError(f"voxel size {voxel} µm in the metadata is not three sizes > 0; reconstruct it again")
    if data.ndim != len(axes) or any(a not in "TCZYX" for a in axes):
        raise SsdpcError(
            f"unexpected axes {axes!r} for data of shape {data.shape}; "
            "write results with napari-ssdpc (axes ZYX or TZYX)"
        )
    if "C" in axes:
        i = axes.index("C")
        q = desc.get("quantity")
        names = desc.get("channels") or CHANNELS.get(q) or [f"{q} {k}" for k in range(data.shape[i])]
        rest = axes.replace("C", "")
        return [
            _result_layers(data[(slice(None),) * i + (k,)], rest, {**desc, "quantity": name}, voxel, limits)[0]
            for k, name in enumerate(names)
        ]
    shape = (1, *data.shape[-2:]) if is_map(desc.get("quantity", "ri")) else data.shape[-3:]
    origin = _origin(desc, shape, voxel)
    return [
        result_layer(
            data, desc.get("quantity", "ri"), voxel, origin, name=desc.get("name", "volume"), info=desc, limits=limits
        )
    ]
