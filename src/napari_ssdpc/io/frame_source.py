"""Raw frames of a series, read one at a time: a memory map of an uncompressed TIFF, else one
page at a time, a (t, y, x) OME-Zarr image (a camera's recording) one chunk at a time, or an
in-memory array; truncated and foreign files are refused up front."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import file_times, os_error
from napari_ssdpc.io.frames import complete_pages

__all__ = ["StoredFrames", "PagedSeries"]


class StoredFrames:
    """Raw frames (t, y, x) of a TIFF series or an OME-Zarr image, read one at a time; or an
    in-memory or lazy (dask) array (a dask array is named by its graph: frames simulated or read
    on demand are not read to hash them).

    Pickles as its path (Dask workers reopen the file themselves).

    Parameters
    ----------
    source : str, Path or array, (t, y, x) or (y, x)
        The file, or the frames.
    label : str, optional
        What messages call frames given as an array (the file they were read from); default 'array'.
    """

    def __init__(self, source, label: str | None = None):
        self._label = label
        in_memory = not isinstance(source, (str, Path))  # a NumPy array, or a lazy (dask) one
        if in_memory and not (hasattr(source, "ndim") and hasattr(source, "shape") and hasattr(source, "dtype")):
            raise SsdpcError(
                f"frames: give a TIFF path, an OME-Zarr folder or a (t, y, x) array, got {type(source).__name__}"
            )
        self.path = None if in_memory else Path(source)
        self._array = source if in_memory else None
        self._data = None
        a = self._open()
        if a.ndim not in (2, 3):
            raise SsdpcError(f"{self.name}: expected a 2D frame or a (t, y, x) series, got shape {a.shape}")
        self.shape = tuple(int(v) for v in a.shape)
        if a.ndim == 2:
            self.shape = (1,) + self.shape
        self.dtype = a.dtype

    @property
    def name(self) -> str:
        """The file's absolute path, or the label of frames in memory ('array' without one)."""
        return (self._label or "array") if self.path is None else str(self.path.resolve())

    @property
    def fingerprint(self) -> str:
        """The path, or for an array a hash of its content."""
        return self.name if self.path is not None else "array:" + self.identity()["sha256"][:16]

    def identity(self) -> dict:
        """What the frames are: path, size (bytes), modification time (ns), frame count and the
        SHA-256 of the file's (or the array's) content.

        Returns
        -------
        dict
        """
        h = hashlib.sha256()
        if self.path is None and not isinstance(self._array, np.ndarray):  # lazy: its graph names it
            token = str(getattr(self._array, "name", ""))
            if not token:
                raise SsdpcError("a series must be a file, a NumPy array or a dask array; save it as a TIFF first")
            h.update(f"{self._array.dtype}{self._array.shape}{token}".encode())
            return {"path": "lazy array", "size": None, "mtime_ns": None, "frames": len(self), "sha256": h.hexdigest()}
        if self.path is None:
            a = np.ascontiguousarray(self._array)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
            return {
                "path": "array",
                "size": int(a.nbytes),
                "mtime_ns": None,
                "frames": len(self),
                "sha256": h.hexdigest(),
            }
        files = sorted(p for p in self.path.rglob("*") if p.is_file()) if self.path.is_dir() else [self.path]
        try:
            size, mtime, ctime = file_times(self.path)
            for path in files:  # a store's files in a fixed order, names and contents
                h.update(str(path.relative_to(self.path) if path != self.path else "").encode())
                with open(path, "rb") as f:
                    for block in iter(lambda: f.read(1 << 22), b""):
                        h.update(block)
        except OSError as e:
            raise os_error(e, self.path, "reading") from None
        return {
            "path": self.name,
            "size": int(size),
            "mtime_ns": int(mtime),
            "ctime_ns": int(ctime),  # moves on any rewrite, also one that keeps the size and time (cp -p)
            "frames": len(self),
            "sha256": h.hexdigest(),
        }

    def _open(self):
        if self._array is not None:
            return self._array
        if self._data is None:
            self._data = _open_zarr(self.path) if self.path.is_dir() else _open_tiff(self.path)
        return self._data

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def frame_shape(self) -> tuple[int, int]:
        """(H, W) of a frame, px."""
        return (self.shape[1], self.shape[2])

    def available(self) -> int:
        """Every frame of a file or an array can be read now."""
        return self.shape[0]

    def finished(self) -> bool:
        """A file or an array holds all its frames."""
        return True

    def wait(self, timeout_s: float) -> None:
        """Nothing to wait for: every frame is there.

        Parameters
        ----------
        timeout_s : float
            Unused (the protocol's longest wait, s).
        """

    def __getitem__(self, t) -> np.ndarray:
        if not 0 <= int(t) < self.shape[0]:
            raise IndexError(f"frame {t} of {self.shape[0]}")
        a = self._open()
        frame = a[int(t)] if a.ndim == 3 else (a[0] if isinstance(a, (PagedSeries, _Squeezed)) else a)
        return np.array(frame, copy=True)  # detach from the memory map

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_data"] = None
        return state


def _open_zarr(path: Path):
    """The raw frames of an OME-Zarr image (its first resolution level) or of a plain zarr array,
    without the axes of length 1: (t, y, x) or (y, x)."""
    import zarr

    try:
        node = zarr.open(str(path), mode="r")
        if not hasattr(node, "shape"):  # a group: an OME-Zarr image names its levels
            level = node.attrs.get("multiscales", [{}])[0].get("datasets", [{"path": "0"}])[0]["path"]
            node = node[level]
    except Exception as e:  # zarr raises many types for folders that hold no store
        raise SsdpcError(
            f"{path}: not a readable OME-Zarr image of raw frames ({type(e).__name__}); give a TIFF or an OME-Zarr"
        ) from None
    keep = tuple(0 if n == 1 else slice(None) for n in node.shape[:-2])
    if sum(1 for k in keep if k != 0) > 1:
        raise SsdpcError(f"{path}: expected (t, y, x) raw frames, got shape {node.shape}")
    return _Squeezed(node, keep)


class _Squeezed:
    """A zarr array with its length-1 leading axes taken away, read frame by frame."""

    def __init__(self, array, keep):
        self._a, self._keep = array, keep
        lead = [n for n, k in zip(array.shape, keep) if k != 0]
        self.shape = (*lead, *array.shape[-2:])
        self.ndim, self.dtype = len(self.shape), array.dtype

    def __getitem__(self, t):
        index = [t if k != 0 else 0 for k in self._keep] if self.ndim == 3 else list(self._keep)
        return np.asarray(self._a[tuple(index)])


def _open_tiff(path: Path):
    """A memory map of an uncompressed TIFF series, else a lazy page-by-page reader; a file of
    one-page series of one shape (frames appended one by one) is a series of those pages."""
    import tifffile

    if not path.is_file():
        raise SsdpcError(f"file not found: {path} (check the path)")
    appended = _appended_frames(path)
    if appended is not None:
        return appended
    try:
        return np.squeeze(tifffile.memmap(path, mode="r"))
    except Exception:  # compressed, tiled or not contiguous: read page by page
        pass
    try:
        tif = tifffile.TiffFile(path)
        series = tif.series[0]
        size = path.stat().st_size
        frames = int(np.prod(series.shape[:-2])) if len(series.shape) > 2 else 1
        if len(tif.pages) < frames and not tif.is_imagej:
            raise SsdpcError(f"{path}: truncated ({len(tif.pages)} of {frames} frames); copy the file again")
        k = complete_pages(tif.pages, size)  # a truncated copy: refuse it now, not at frame k
        if k < len(tif.pages):
            raise SsdpcError(f"{path}: truncated (page {k} ends beyond the file's end); copy the file again")
    except SsdpcError:
        raise
    except Exception as e:  # tifffile raises many types for foreign or truncated files
        raise SsdpcError(
            f"{path}: not a readable TIFF ({type(e).__name__}); give a complete TIFF or OME-TIFF series"
        ) from None
    return PagedSeries(tif, series)


def _appended_frames(path: Path):
    """A :class:`PagedSeries` of the pages when the file holds several one-frame series of one
    shape and type (each frame appended as its own series), else None."""
    import tifffile

    try:
        tif = tifffile.TiffFile(path)
    except Exception:
        return None  # reported by the readers below
    kinds = {(tuple(s.shape), str(s.dtype)) for s in tif.series}
    if len(tif.series) < 2 or len(kinds) != 1 or len(next(iter(kinds))[0]) != 2:
        tif.close()
        return None
    return PagedSeries(tif, None)


class PagedSeries:
    """(t, y, x) view of a TIFF series that decodes one page per frame.

    Parameters
    ----------
    tif : tifffile.TiffFile
    series : tifffile.TiffPageSeries or None
        The series of frames; None: every series of the file is one frame (pages appended).
    """

    def __init__(self, tif, series):
        self._appended = series is None
        if series is None:
            first = tif.series[0]
            shape, dtype = (len(tif.series), *first.shape), first.dtype
        else:
            shape, dtype = tuple(s for s in series.shape if s != 1), series.dtype
        if len(shape) not in (2, 3):
            raise SsdpcError(f"{tif.filename}: expected a 2D frame or a (t, y, x) series, got shape {series.shape}")
        self._tif, self.shape, self.dtype = tif, shape, dtype
        self.ndim = len(shape)

    def __getitem__(self, t):
        try:
            if self._appended:
                return self._tif.series[int(t)].asarray()
            return self._tif.asarray(key=int(t) if self.ndim == 3 else 0, series=0).reshape(self.shape[-2:])
        except Exception as e:  # a damaged page
            name = self._tif.filename
            raise SsdpcError(f"{name}: frame {t} cannot be read ({type(e).__name__}); check the file") from None
