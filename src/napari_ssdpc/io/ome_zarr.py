"""OME-Zarr images: the NGFF metadata, creating an image group, the root image, reading one back.

Series stores (:mod:`.store`) and the napari writer build on these.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from napari_ssdpc._version import SOFTWARE
from napari_ssdpc.errors import SsdpcError

__all__ = ["create_ome_zarr", "link_root_image", "ngff_multiscales", "read_ome_zarr"]


def ngff_multiscales(axes: str, voxel_um, name: str, origin_um=None) -> list:
    """OME-NGFF 0.4 ``multiscales`` metadata for one resolution level '0'.

    Parameters
    ----------
    axes : str
        'ZYX', 'TZYX', 'YX', 'TYX' or 'TCZYX'; time steps are in frames.
    voxel_um : sequence of float
        (dz, dy, dx) in µm; a 2D map uses the last two.
    name : str
        The image's name.
    origin_um : sequence of float, optional
        (z, y, x) position of voxel 0 in µm (an NGFF translation); a 2D map uses the last two.

    Returns
    -------
    list of dict
        The ``multiscales`` attribute (axes with units, scale and translation).
    """
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
    spatial = sum(a in "ZYX" for a in axes.upper())
    lead = [0.0] * (len(axes) - spatial)
    transforms = [{"type": "scale", "scale": [1.0] * len(lead) + [float(v) for v in voxel_um][-spatial:]}]
    if origin_um is not None:
        transforms.append({"type": "translation", "translation": lead + [float(v) for v in origin_um][-spatial:]})
    return [
        {
            "version": "0.4",
            "name": name,
            "axes": ax,
            "datasets": [{"path": "0", "coordinateTransformations": transforms}],
        }
    ]


def link_root_image(root, name: str = "ri") -> None:
    """Make the store's root an NGFF image too, pointing at ``name``'s arrays.

    A store holds one image group per quantity; NGFF readers that look only at the root
    (ome-zarr-py, napari-ome-zarr, Fiji) then open the RI volume.

    Parameters
    ----------
    root : zarr.Group
        The store's root group, opened for writing.
    name : str
        The image group the root shows.
    """
    ms = [dict(m) for m in root[name].attrs["multiscales"]]
    ms[0]["datasets"] = [{**d, "path": f"{name}/{d['path']}"} for d in ms[0]["datasets"]]
    root.attrs["multiscales"] = ms


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
    origin_um=None,
    digits=None,
):
    """Create (or open for appending) the image group ``path/name`` of an OME-Zarr store.

    Parameters
    ----------
    path : str or Path
        The ``.zarr`` store (created if new).
    name : str
        Image group ('ri', 'phase', ...); the 'ri' group is also linked from the root.
    shape : tuple of int
        Full array shape, e.g. (t, z, y, x).
    axes : str
        Axes of ``shape`` ('TZYX', 'TYX', ...).
    voxel_um : sequence of float
        (dz, dy, dx), µm.
    chunks : tuple of int, optional
        Default: one chunk per frame.
    attrs : dict, optional
        Kept under the group's ``napari_ssdpc`` attribute.
    dtype : str
    overwrite : bool
        Replace an existing group of that name.
    origin_um : sequence of float, optional
        (z, y, x) position of voxel 0, µm (the NGFF translation).
    digits : int, optional
        Decimal digits kept of every value (numcodecs ``Quantize``, then zstd with bit shuffle):
        the error is below 10^-digits and the chunks compress several-fold. None: exact.

    Returns
    -------
    zarr.Array
        Level '0' of the image, filled with NaN.
    """
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
    grp.attrs["multiscales"] = ngff_multiscales(axes, voxel_um, name, origin_um)
    grp.attrs["napari_ssdpc"] = {"software": SOFTWARE, **(attrs or {})}  # how readers know our images
    spatial = sum(a in "ZYX" for a in axes.upper())
    chunks = chunks or ((1,) * (len(shape) - spatial) + tuple(shape[-spatial:]))
    arr = grp.create_array(
        "0", shape=tuple(shape), chunks=tuple(chunks), dtype=dtype, fill_value=np.nan, **_codecs(digits, dtype)
    )
    if name == "ri":
        link_root_image(root, name)
    return arr


def _codecs(digits, dtype) -> dict:
    """Filters and compressors of an image: exact (zarr's defaults), or quantised to ``digits``."""
    if digits is None:
        return {}
    import numcodecs

    return {
        "filters": [numcodecs.Quantize(digits=int(digits), dtype=np.dtype(dtype).str)],
        "compressors": [numcodecs.Blosc(cname="zstd", clevel=5, shuffle=numcodecs.Blosc.BITSHUFFLE)],
    }


def read_ome_zarr(path, name: str = "ri"):
    """An image group written by :func:`create_ome_zarr`.

    Parameters
    ----------
    path : str or Path
        The ``.zarr`` store.
    name : str
        The image group ('ri', 'phase', ...).

    Returns
    -------
    data : zarr.Array
        Level '0', e.g. (t, z, y, x).
    voxel_um : tuple of float
        (dz, dy, dx), µm.
    attrs : dict
        Our metadata (``napari_ssdpc`` attribute).
    """
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
