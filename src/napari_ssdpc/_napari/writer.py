"""napari writer: result layers (RI, phase, absorption, ...) to OME-TIFF or OME-Zarr.

A (z, y, x) layer goes to OME-TIFF (``.ome.tif``) or OME-Zarr (``.zarr``); a (t, z, y, x) time
series goes to OME-Zarr (one chunk per time point) or, if asked, to a TZYX OME-TIFF. An OME-Zarr
store holds one image group per quantity ('ri', 'phase', ...), as ``ssdpc reconstruct`` writes it,
so saving the RI and the phase layer to the same ``NAME.zarr`` puts both in one store.
Voxel sizes in µm are written in the standard metadata (OME PhysicalSize*, NGFF
coordinateTransformations), and our own description (quantity, origin, settings) as JSON, which
``_reader.get_result_reader`` recognises. Both writers are atomic: the output appears complete or
not at all.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from napari_ssdpc._napari.reader import RESULT_FORMAT, RESULT_VERSION, zarr_images
from napari_ssdpc._version import SOFTWARE
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.frames import write_ome_tiff
from napari_ssdpc.io.paths import is_ours


def write_volume(path: str, data, meta: dict) -> list[str]:
    """npe2 single-layer writer for image layers of 3 or 4 dimensions.

    Parameters
    ----------
    path : str
        ``.ome.tif`` or ``.zarr``.
    data : array_like
        (z, y, x) or (t, z, y, x).
    meta : dict
        The layer's attributes (scale, translate, metadata).

    Returns
    -------
    list of str
        The paths written.
    """
    meta = meta if isinstance(meta, dict) else {}
    data = data[0] if isinstance(data, (list, tuple)) and data else data  # multiscale: the full resolution
    name = meta.get("name") or "volume"
    if not (hasattr(data, "ndim") and hasattr(data, "dtype")) or np.dtype(data.dtype).kind not in "uif":
        raise SsdpcError(f"layer '{name}' holds no numeric image ({type(data).__name__}); pick a reconstruction layer")
    if data.ndim not in (3, 4):
        raise SsdpcError(
            f"layer '{name}' has {data.ndim} dimensions; the ssDPC writer saves "
            "(z, y, x) volumes or (t, z, y, x) series: pick a reconstruction layer"
        )
    metadata = meta.get("metadata") if isinstance(meta.get("metadata"), dict) else {}
    info = dict(metadata.get("ssdpc") if isinstance(metadata.get("ssdpc"), dict) else {})
    scale = _per_axis(meta.get("scale"), data.ndim, 1.0, "scale", name)
    translate = _per_axis(meta.get("translate"), data.ndim, 0.0, "translate", name)
    info.setdefault("quantity", "ri")
    info["name"] = str(name)
    return [str(write_result(path, data, voxel_um=scale, origin_um=translate, info=info))]


def _per_axis(values, ndim: int, default: float, what: str, name: str) -> list[float]:
    """The last three (z, y, x) of a layer's per-axis ``scale`` or ``translate``, checked."""
    if values is None:
        return [default] * 3
    try:
        v = [float(x) for x in values]
    except (TypeError, ValueError):
        raise SsdpcError(f"layer '{name}': its {what} {values!r} is not a list of numbers; reset it") from None
    if len(v) != ndim:
        raise SsdpcError(f"layer '{name}': its {what} has {len(v)} values for {ndim} axes; give one per axis")
    return v[-3:]


def _check_grid(voxel_um, origin_um) -> None:
    """Voxel sizes finite and > 0 µm, an origin of three finite numbers."""
    vox, org = np.asarray(voxel_um, float).ravel(), np.asarray(origin_um, float).ravel()
    if vox.size != 3 or not (np.isfinite(vox).all() and (vox > 0).all()):
        raise SsdpcError(f"voxel size {list(voxel_um)} µm: give three finite sizes > 0 (dz, dy, dx), µm")
    if org.size != 3 or not np.isfinite(org).all():
        raise SsdpcError(f"origin {list(origin_um)} µm: give three finite numbers (z, y, x), µm")


def write_result(path, data, *, voxel_um, origin_um=(0.0, 0.0, 0.0), info: dict | None = None) -> Path:
    """Write a (z, y, x) or (t, z, y, x) result; ``.zarr`` -> OME-Zarr, else OME-TIFF.

    Parameters
    ----------
    path : str or Path
    data : array_like
    voxel_um : sequence of float
        (dz, dy, dx), µm.
    origin_um : sequence of float
        (z, y, x) of voxel 0, µm.
    info : dict, optional
        Our metadata (settings, optics, quantity).

    Returns
    -------
    Path
    """
    path = Path(path)
    if not (hasattr(data, "ndim") and hasattr(data, "dtype")) or np.dtype(data.dtype).kind not in "uif":
        raise SsdpcError(f"{path.name}: no numeric image to write ({type(data).__name__}); give a (z, y, x) array")
    _check_grid(voxel_um, origin_um)
    desc = _description(info, voxel_um, origin_um)
    q = str(desc.get("quantity", "ri"))
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_ -]{0,63}", q):  # a group name in the store: no '/', no '..'
        raise SsdpcError(f"quantity name {q!r}: use letters, digits and '_' only (e.g. 'ri', 'phase')")
    if path.suffix.lower() == ".zarr":
        return write_ome_zarr(path, data, name=q, voxel_um=voxel_um, origin_um=origin_um, attrs=desc)
    if not path.name.lower().endswith((".ome.tif", ".ome.tiff")):
        raise SsdpcError(f"{path.name}: save results as NAME.ome.tif (a volume) or NAME.zarr (a time series)")
    if path.exists() and not is_ours(path):
        raise SsdpcError(f"{path} is a file napari-ssdpc did not write; save the layer under a new name")
    axes = "TZYX" if np.ndim(data) == 4 else "ZYX"
    return write_ome_tiff(path, np.asarray(data, np.float32), axes=axes, voxel_um=voxel_um, description=desc)


def _description(info, voxel_um, origin_um) -> dict:
    d = {k: v for k, v in dict(info or {}).items() if k != "kind"}
    d.update(
        format=RESULT_FORMAT,
        version=RESULT_VERSION,
        voxel_um=[float(v) for v in voxel_um],
        origin_um=[float(v) for v in origin_um],
        software=SOFTWARE,
    )
    return _jsonable(d)


def _jsonable(obj):
    """Plain JSON types (numpy scalars and arrays become numbers and lists)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if obj is None or isinstance(obj, (str, int, float, bool)):
        return obj
    return str(obj)  # anything else a layer's metadata may hold, by its name


def write_ome_zarr(path, data, *, name: str, voxel_um, origin_um=(0.0, 0.0, 0.0), attrs: dict | None = None) -> Path:
    """Image group ``name`` (e.g. 'ri') of the OME-Zarr store ``path``, in the layout of
    ``io.ome_zarr.create_ome_zarr`` that ``ssdpc reconstruct`` writes: OME-NGFF 0.4, zarr format 2,
    one chunk per time point, scale and translation in µm. Other image groups in the store are
    kept. The group is written into a temporary store next to ``path`` and moved into place.

    Parameters
    ----------
    path : str or Path
    data : array_like
    name : str
    voxel_um : sequence of float
    origin_um : sequence of float
    attrs : dict, optional

    Returns
    -------
    Path
    """
    import zarr

    from napari_ssdpc.io.ome_zarr import create_ome_zarr, link_root_image

    path = Path(path)
    if not path.parent.exists():
        raise SsdpcError(f"output folder does not exist: {path.parent} (create it first)")
    if path.exists() and not path.is_dir():
        raise SsdpcError(f"{path} exists and is not a folder; choose another name for the OME-Zarr output")
    if path.is_dir():
        _check_own_store(path)
    nd = np.ndim(data)
    if nd not in (3, 4):
        raise SsdpcError(f"OME-Zarr output needs (z, y, x) or (t, z, y, x) data, got shape {np.shape(data)}")
    shape = tuple(int(n) for n in np.shape(data))
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent))
    try:
        arr = create_ome_zarr(
            tmp, name, shape, "TZYX"[-nd:], voxel_um, attrs=attrs, overwrite=True, origin_um=origin_um
        )
        for idx in np.ndindex(*shape[:-3]):  # one time point at a time (dask-friendly)
            arr[idx] = np.asarray(data[idx], np.float32)
        root = zarr.open_group(str(path), mode="a", zarr_format=2)  # the store (created if new)
        _replace_dir(tmp / name, path / name)
        if name == "ri":  # NGFF readers that look at the root open the RI volume
            link_root_image(root, name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return path


def _check_own_store(path: Path) -> None:
    """An existing folder is written into only when it is an empty folder or a store of
    result layers this writer made; another program's store and a time series of
    ``ssdpc reconstruct`` (whose stamp names its images) are refused before anything is written."""
    from napari_ssdpc.io.store import STAMP

    if not any(path.iterdir()):
        return
    try:
        import zarr

        root = zarr.open_group(str(path), mode="r")
        series = STAMP in root.attrs
        ours = bool(zarr_images(path))
    except Exception:  # not a zarr store at all
        series, ours = False, False
    if series:
        raise SsdpcError(f"{path} is a time series written by ssdpc reconstruct; save the layer to a new NAME.zarr")
    if not ours:
        raise SsdpcError(f"{path} holds data napari-ssdpc did not write; save the layer to a new NAME.zarr")


def _replace_dir(src: Path, dst: Path):
    """Move folder ``src`` to ``dst``, replacing an existing ``dst`` only after ``src`` is complete."""
    if dst.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{dst.name}.", suffix=".old", dir=dst.parent))
        os.rmdir(old)
        os.replace(dst, old)
        os.replace(src, dst)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(src, dst)
