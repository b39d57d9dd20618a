"""Readers and writers: raw frames (TIFF), volumes (OME-TIFF), JSON (OME-Zarr: :mod:`.ome_zarr`).

Every writer goes through :func:`atomic_write`: the file appears complete or not at
all, so an error never leaves a half-written file over a good one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tifffile

from napari_ssdpc._version import SOFTWARE
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import atomic_write_set

__all__ = [
    "TiffInfo",
    "complete_pages",
    "read_frame",
    "read_stack",
    "tiff_info",
    "write_ome_tiff",
    "write_ome_tiffs",
    "write_tiff",
    "write_tiffs",
]


@dataclass(frozen=True)
class TiffInfo:
    """What a TIFF says about itself: its first series' layout and its metadata, not its pixels.

    Attributes
    ----------
    axes : str
        The first series' axes as tifffile names them ("YX", "TYX", "IYX", "ZYX", "YXS", ...).
    shape : tuple of int
        The first series' shape, one entry per axis.
    dtype : numpy.dtype
    samples : int
        Samples per pixel of the first page (3 or 4: a colour image).
    description : str
        The first page's ImageDescription (the OME-XML of an OME-TIFF).
    software : str
        The first page's Software tag.
    ome : dict or None
        The first OME ``Image`` element (``tifffile.xml2dict``; its ``Description`` and ``Pixels``)
        of an OME-TIFF, else None.
    complete : bool
        The pixels of the first series' last page lie inside the file (a truncated copy or an
        interrupted transfer ends early, and would fail only when that frame is read).
    """

    axes: str
    shape: tuple
    dtype: np.dtype
    samples: int
    description: str
    software: str
    ome: dict | None
    complete: bool


def tiff_info(path) -> TiffInfo:
    """Open a TIFF and read what it says about itself (:class:`TiffInfo`), not its pixels.

    Parameters
    ----------
    path : str or Path
        The TIFF or OME-TIFF file.

    Returns
    -------
    TiffInfo

    Raises
    ------
    Exception
        Whatever tifffile raises for a file that is not a TIFF it can parse (``OSError`` for one
        that cannot be opened); the caller decides what that means.
    """
    path = Path(path)
    with tifffile.TiffFile(path) as tif:
        return _info(tif, path.stat().st_size)


def _info(tif, size: int) -> TiffInfo:
    """:class:`TiffInfo` of an open ``tifffile.TiffFile`` of ``size`` bytes."""
    page = tif.pages[0]
    series = tif.series[0] if tif.series else None
    ome = None
    if tif.is_ome:
        try:
            image = tifffile.xml2dict(tif.ome_metadata)["OME"]["Image"]
            ome = image[0] if isinstance(image, list) else image
        except (KeyError, TypeError, ValueError, AttributeError):
            ome = None
    return TiffInfo(
        axes=series.axes if series is not None else "",
        shape=tuple(series.shape) if series is not None else tuple(page.shape),
        dtype=np.dtype(series.dtype if series is not None else page.dtype),
        samples=int(getattr(page, "samplesperpixel", 1)),
        description=str(getattr(page, "description", "") or ""),
        software=str(getattr(page, "software", "") or ""),
        ome=ome if isinstance(ome, dict) else None,
        complete=series is not None and _complete(series, size),
    )


def _complete(series, size: int) -> bool:
    """Whether the pixels of a series' last page lie inside a file of ``size`` bytes."""
    pages = series.pages
    return bool(len(pages)) and complete_pages([pages[len(pages) - 1]], size) == 1


def complete_pages(pages, size: int) -> int:
    """How many of the leading ``pages`` hold all their pixels inside a file of ``size`` bytes.

    A page whose data run past the file's end, or that has none yet (a header being written),
    ends the count: the file was cut short or is still being written.

    Parameters
    ----------
    pages : iterable of tifffile.TiffPage
    size : int
        The file's size, bytes.

    Returns
    -------
    int
    """
    n = 0
    for page in pages:
        offsets, counts = getattr(page, "dataoffsets", ()), getattr(page, "databytecounts", ())
        if not offsets or any(c <= 0 or o + c > size for o, c in zip(offsets, counts)):
            break
        n += 1
    return n


def read_frame(path, *, allow_series: bool = True, name: str = "frame") -> np.ndarray:
    """Read a raw light-field frame (y, x) or series (t, y, x) from a TIFF/OME-TIFF.

    Parameters
    ----------
    path : str or Path
        The TIFF file.
    allow_series : bool
        Accept a (t, y, x) series; else only one frame.
    name : str
        The frame's role, for the messages ("frame", "flat frame", "white frame").

    Returns
    -------
    numpy.ndarray
        (y, x) or (t, y, x), the file's dtype.

    Raises
    ------
    SsdpcError
        Missing, unreadable, truncated, colour (RGB) or a reconstruction result.
    """
    path = Path(path)
    data = np.squeeze(_read(path, name, _check_kind))
    if data.ndim == 3 and not allow_series:
        raise SsdpcError(f"{path}: holds {data.shape[0]} frames; give a single {name} (y, x)")
    if data.ndim not in (2, 3):
        raise SsdpcError(f"{path}: expected a 2D frame or a (t, y, x) series, got shape {data.shape}")
    return data


def read_stack(path, *, name: str = "stack") -> np.ndarray:
    """Read an image stack of any shape (a DPC stack: patterns, focal planes, y, x) from a TIFF.

    Parameters
    ----------
    path : str or Path
        The TIFF or OME-TIFF file.
    name : str
        Its role, for the messages.

    Returns
    -------
    numpy.ndarray
        The file's images in its own order and shape, singleton axes dropped; the samples of a
        colour (RGB) file are images of their own, first (three images written as one RGB page).

    Raises
    ------
    SsdpcError
        Missing, unreadable, truncated or a reconstruction result.
    """
    seen: dict = {}

    def check(info, p, what):
        _check_result(info, p, what)
        seen["axes"] = info.axes

    data = _read(Path(path), name, check)
    if str(seen.get("axes", "")).endswith("S") and data.ndim >= 3:  # interleaved samples: one image each
        data = np.moveaxis(data, -1, 0)
    return np.squeeze(data)


def _read(path: Path, name: str, check) -> np.ndarray:
    """A TIFF's images after ``check(info, path, name)``; every failure one line."""
    if path.is_dir():
        raise SsdpcError(f"{name} {path} is a folder; give a TIFF file")
    if not path.is_file():
        raise SsdpcError(f"file not found: {path} (check the path)")
    try:
        with tifffile.TiffFile(path) as tif:
            check(_info(tif, path.stat().st_size), path, name)
            return tif.asarray()
    except SsdpcError:
        raise
    except OSError as e:
        raise SsdpcError(f"{path}: cannot be read ({e.strerror or type(e).__name__}); check the file") from None
    except Exception as e:  # tifffile raises many types for foreign or truncated files
        raise SsdpcError(
            f"{path}: not a readable TIFF ({type(e).__name__}); give a complete TIFF or OME-TIFF {name}"
        ) from None


def _check_not_result(info: TiffInfo, path: Path, name: str) -> None:
    """Refuse colour images and ssdpc results given where camera images belong."""
    if info.samples > 1 or "S" in info.axes:
        raise SsdpcError(
            f"{path}: a colour (RGB) image, not camera images; give the monochrome camera images "
            "(export them as greyscale TIFF without colour conversion)"
        )
    _check_result(info, path, name)


def _check_result(info: TiffInfo, path: Path, name: str) -> None:
    """Refuse an ssdpc result given where camera images belong."""
    text = info.description
    if "napari-ssdpc" in text and "quantity" in text:
        what = next((q for q in ("refractive index", "phase", "absorption", "DPC") if q in text), "a volume")
        raise SsdpcError(
            f"{path}: a reconstruction result ({what}) of napari-ssdpc, not a {name} of camera images; "
            "give the camera images the result was computed from"
        )


def _check_kind(info: TiffInfo, path: Path, name: str) -> None:
    """Refuse colour images, ssdpc results and z stacks given where a raw camera frame belongs."""
    _check_not_result(info, path, name)
    if "Z" in info.axes:
        raise SsdpcError(
            f"{path}: a z stack (axes {info.axes}), not a raw camera {name}; give the light-field frame (y, x)"
        )


def write_tiff(path, data, *, metadata=None, **kwargs) -> Path:
    """Write a (multi-page) TIFF atomically.

    Parameters
    ----------
    path : str or Path
    data : array_like
        (y, x) frame or (t, y, x) series.
    metadata : dict, optional
        tifffile metadata; a series gets ``{"axes": "TYX"}``.
    **kwargs
        Passed to ``tifffile.imwrite``.

    Returns
    -------
    Path
    """
    return write_tiffs({path: data}, metadata=metadata, **kwargs)[0]


def write_tiffs(files: dict, *, metadata=None, **kwargs) -> list[Path]:
    """Write several TIFFs as one unit (all complete before any is renamed into place).

    Parameters
    ----------
    files : dict
        ``{path: data}``.
    metadata : dict, optional
        As for :func:`write_tiff`.
    **kwargs
        Passed to ``tifffile.imwrite``.

    Returns
    -------
    list of Path
    """
    paths = [Path(p) for p in files]
    kwargs.setdefault("photometric", "minisblack")  # a (3, H, W) series is frames, not RGB planes
    kwargs.setdefault("software", SOFTWARE)  # TIFF tag 305: how io.paths.is_ours knows our files
    with atomic_write_set(paths) as temps:
        for tmp, data in zip(temps, files.values()):
            data = np.asarray(data)
            meta = {"axes": "TYX"} if metadata is None and data.ndim == 3 else metadata
            tifffile.imwrite(tmp, data, metadata=meta, **kwargs)
    return paths


def _ome_meta(axes: str, voxel_um=None, description: dict | None = None) -> dict:
    meta: dict = {"axes": axes}
    if voxel_um is not None:  # (dz, dy, dx), or (dy, dx) for a 2D image
        for axis, size in zip("ZYX"[3 - len(voxel_um) :], voxel_um):
            meta[f"PhysicalSize{axis}"] = float(size)
            meta[f"PhysicalSize{axis}Unit"] = "µm"
    if description:
        meta["Description"] = json.dumps({"software": SOFTWARE, **description})
    return meta


def write_ome_tiff(path, data, *, axes: str, voxel_um=None, description: dict | None = None) -> Path:
    """Write an OME-TIFF atomically, with physical pixel sizes and a JSON description.

    Parameters
    ----------
    path : str or Path
        The file.
    data : array_like
        The image.
    axes : str
        OME axes, like 'ZYX' or 'TZYX'.
    voxel_um : tuple of float, optional
        (dz, dy, dx) in µm, or (dy, dx) for a 2D image.
    description : dict, optional
        Stored as JSON in the OME metadata.

    Returns
    -------
    Path
    """
    return write_ome_tiffs({path: (data, axes, voxel_um, description)})[0]


def write_ome_tiffs(files: dict) -> list[Path]:
    """Write several OME-TIFFs as one unit: every file is complete before any is renamed into
    place, so a failure (a full disk) leaves all the old files, never a mixed set.

    Parameters
    ----------
    files : dict
        ``{path: (data, axes, voxel_um, description)}`` as for :func:`write_ome_tiff`.

    Returns
    -------
    list of Path
    """
    paths = [Path(p) for p in files]
    with atomic_write_set(paths) as temps:
        for tmp, (data, axes, voxel_um, description) in zip(temps, files.values()):
            meta = _ome_meta(axes, voxel_um, description)
            tifffile.imwrite(tmp, np.asarray(data), ome=True, photometric="minisblack", metadata=meta)
    return paths
