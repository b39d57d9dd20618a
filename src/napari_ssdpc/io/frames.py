"""Readers and writers: raw frames (TIFF), volumes (OME-TIFF), JSON.

Every writer goes through :func:`atomic_write`: the file appears complete or not at
all, so an error never leaves a half-written file over a good one.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import tifffile

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import atomic_write


def read_frame(path, *, allow_series: bool = True) -> np.ndarray:
    """Read a raw light-field frame (y, x) or series (t, y, x) from a TIFF/OME-TIFF."""
    path = Path(path)
    if not path.is_file():
        raise SsdpcError(f"file not found: {path} (check the path)")
    try:
        data = tifffile.imread(path)
    except Exception as e:  # tifffile raises many types for foreign files
        raise SsdpcError(f"{path}: not a readable TIFF ({type(e).__name__}); give a TIFF or OME-TIFF frame") from None
    data = np.squeeze(data)
    if data.ndim == 3 and not allow_series:
        raise SsdpcError(f"{path}: holds {data.shape[0]} frames; give a single frame (y, x)")
    if data.ndim not in (2, 3):
        raise SsdpcError(f"{path}: expected a 2D frame or a (t, y, x) series, got shape {data.shape}")
    return data


def write_tiff(path, data, *, metadata=None, **kwargs) -> Path:
    """Write a (multi-page) TIFF atomically."""
    path = Path(path)
    data = np.asarray(data)
    kwargs.setdefault("photometric", "minisblack")  # a (3, H, W) series is frames, not RGB planes
    if metadata is None and data.ndim == 3:
        metadata = {"axes": "TYX"}
    with atomic_write(path) as tmp:
        tifffile.imwrite(tmp, data, metadata=metadata, **kwargs)
    return path


def write_ome_tiff(path, data, *, axes: str, voxel_um=None, description: dict | None = None) -> Path:
    """Write an OME-TIFF with physical pixel sizes (µm) and a JSON description in the
    OME metadata. ``axes`` like 'ZYX' or 'TZYX'; ``voxel_um`` is (dz, dy, dx)."""
    meta = {"axes": axes}
    if voxel_um is not None:
        dz, dy, dx = (float(v) for v in voxel_um)
        meta.update(
            PhysicalSizeZ=dz,
            PhysicalSizeZUnit="µm",
            PhysicalSizeY=dy,
            PhysicalSizeYUnit="µm",
            PhysicalSizeX=dx,
            PhysicalSizeXUnit="µm",
        )
    if description:
        meta["Description"] = json.dumps(description)
    path = Path(path)
    with atomic_write(path) as tmp:
        tifffile.imwrite(tmp, np.asarray(data), ome=True, metadata=meta)
    return path


# ------------------------------------------------------------------ OME-Zarr
def ngff_multiscales(axes: str, voxel_um, name: str) -> list:
    """OME-NGFF 0.4 ``multiscales`` metadata for one resolution level '0'.
    ``axes`` like 'ZYX' or 'TZYX'; ``voxel_um`` is (dz, dy, dx); time steps are in frames."""
    kinds = {
        "T": ("t", "time", None),
        "C": ("c", "channel", None),
        "Z": ("z", "space", "micrometer"),
        "Y": ("y", "space", "micrometer"),
        "X": ("x", "space", "micrometer"),
    }
    ax = []
    for a in axes.upper():
        n, t, u = kinds[a]
        ax.append({"name": n, "type": t, **({"unit": u} if u else {})})
    scale = [1.0] * (len(axes) - 3) + [float(v) for v in voxel_um]
    return [
        {
            "version": "0.4",
            "name": name,
            "axes": ax,
            "datasets": [{"path": "0", "coordinateTransformations": [{"type": "scale", "scale": scale}]}],
        }
    ]


def create_ome_zarr(
    path,
    name: str,
    shape,
    axes: str,
    voxel_um,
    chunks=None,
    attrs: dict | None = None,
    dtype="float32",
    overwrite=False,
):
    """Create (or open for appending) the image group ``path/name`` of an OME-Zarr store.
    Returns the zarr array of level '0'. One chunk per frame by default."""
    import zarr

    root = zarr.open_group(str(path), mode="a", zarr_format=2)
    if name in root and not overwrite:
        arr = root[name]["0"]
        if tuple(arr.shape) != tuple(shape):
            raise SsdpcError(
                f"{path}/{name} holds shape {tuple(arr.shape)}, not {tuple(shape)}; "
                "write to a new output or delete the old store"
            )
        return arr
    grp = root.create_group(name, overwrite=True)
    grp.attrs["multiscales"] = ngff_multiscales(axes, voxel_um, name)
    if attrs:
        grp.attrs["napari_ssdpc"] = attrs
    chunks = chunks or ((1,) * (len(shape) - 3) + tuple(shape[-3:]))
    return grp.create_array("0", shape=tuple(shape), chunks=tuple(chunks), dtype=dtype, fill_value=np.nan)


def read_ome_zarr(path, name: str = "ri"):
    """(data, voxel_um, attrs) of an image group written by :func:`create_ome_zarr`."""
    import zarr

    path = Path(path)
    if not path.exists():
        raise SsdpcError(f"file not found: {path} (check the path)")
    root = zarr.open_group(str(path), mode="r")
    if name not in root:
        raise SsdpcError(f"{path} has no '{name}' image; it holds {', '.join(sorted(root.group_keys()))}")
    grp = root[name]
    ms = grp.attrs["multiscales"][0]
    scale = ms["datasets"][0]["coordinateTransformations"][0]["scale"]
    return grp["0"], tuple(scale[-3:]), dict(grp.attrs.get("napari_ssdpc", {}))
