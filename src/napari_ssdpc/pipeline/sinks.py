"""Where the frame loop puts its results: memory, OME-TIFF files, a resumable OME-Zarr store.

A sink is opened once with the output grid and the source (it returns the frames it holds
already: a store being resumed), takes every frame's result, and is closed at the end, also
after an error. Storage itself (the files' formats, the store's stamp and lock) is in
:mod:`napari_ssdpc.io`.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.io.frames import write_ome_tiffs
from napari_ssdpc.io.live_store import record_live_frames
from napari_ssdpc.io.store import check_input_unchanged, grow_store, open_store, stamp_of, write_frame
from napari_ssdpc.io.store_lock import StoreLock
from napari_ssdpc.pipeline.sources import grows
from napari_ssdpc.settings.outputs import layout, parse_save

__all__ = ["LatestSink", "MemorySink", "OmeTiffSink", "OutputGrid", "Sink", "ZarrSink"]


@dataclass(frozen=True)
class OutputGrid:
    """The grid every frame's result lies on.

    Attributes
    ----------
    z_um, y_um, x_um : ndarray
        Plane and pixel centres, µm (y = x = 0 on the optical axis).
    settings : dict
        The reconstructor's settings, for the metadata.
    build_seconds : float
        Time the operators took, s.
    """

    z_um: np.ndarray
    y_um: np.ndarray
    x_um: np.ndarray
    settings: dict
    build_seconds: float = 0.0

    @classmethod
    def of(cls, rec) -> OutputGrid:
        """The grid of a Reconstructor.

        Parameters
        ----------
        rec : Reconstructor

        Returns
        -------
        OutputGrid
        """
        return cls(rec.z_um, rec.y_um, rec.x_um, rec.settings(), rec.build_seconds)

    @property
    def voxel_um(self) -> tuple[float, float, float]:
        """(dz, dy, dx), µm."""
        dy = float(self.y_um[1] - self.y_um[0])
        return float(self.settings.get("dz_um", 1.0)), dy, float(self.x_um[1] - self.x_um[0])

    @property
    def origin_um(self) -> tuple[float, float, float]:
        """(z, y, x) of the first voxel, µm."""
        return float(self.z_um[0]), float(self.y_um[0]), float(self.x_um[0])

    def layout(self, save) -> dict:
        """{name: (shape per frame, axes, description)} of RI and ``save``.

        Parameters
        ----------
        save : iterable of str
            Quantities beside RI.

        Returns
        -------
        dict
        """
        return layout(len(self.z_um), (len(self.y_um), len(self.x_um)), save)


class Sink:
    """What the frame loop writes to: opened once, a result per frame, closed at the end.

    Subclasses implement ``_open`` (default: nothing held), ``_write`` and ``_close`` (default:
    nothing to release).
    """

    def open(self, job, grid: OutputGrid, source) -> set[int]:
        """Prepare for the source's frames; return the frames already held (a store being resumed).

        Parameters
        ----------
        job : Job
            What the frames are reconstructed with (its ``result_key`` stamps a store).
        grid : OutputGrid
            Where every frame's result lies.
        source : FrameSource
            The frames to come.

        Returns
        -------
        set of int
        """
        return self._open(job, grid, source)

    def accept(self, t: int, result) -> None:
        """Check frame ``t``'s result before it is written, in the loop's thread, right after it is
        reconstructed (raises to stop the run; the frame is then not written).

        Parameters
        ----------
        t : int
            Frame index.
        result : Result
        """
        self._accept(int(t), result)

    def write(self, t: int, result) -> float:
        """Keep frame ``t``'s result (accepted by :meth:`accept`; possibly in another thread).

        Parameters
        ----------
        t : int
            Frame index.
        result : Result

        Returns
        -------
        float
            Seconds spent writing.
        """
        return self._write(int(t), result)

    def close(self) -> None:
        """Release what :meth:`open` took (also after an error)."""
        self._close()

    def _open(self, job, grid, source) -> set[int]:
        return set()

    def _accept(self, t: int, result) -> None:
        pass

    def _write(self, t: int, result) -> float:
        raise NotImplementedError

    def _close(self) -> None:
        pass


class MemorySink(Sink):
    """Results kept in memory, in frame order (``frames``: {t: kept value}).

    Parameters
    ----------
    keep : callable, optional
        What to keep of each Result (default: the Result itself).
    """

    def __init__(self, keep: Callable[[Any], Any] | None = None):
        self.keep = keep or (lambda r: r)
        self.frames: dict[int, Any] = {}

    def _write(self, t, result) -> float:
        self.frames[t] = self.keep(result)
        return 0.0

    @property
    def last(self):
        """The latest frame's kept value (None before the first)."""
        return self.frames[max(self.frames)] if self.frames else None


class LatestSink(Sink):
    """Only the newest frame's result is kept (``last``: (t, Result)): memory constant however long a
    live run."""

    def __init__(self):
        self.last: tuple[int, Any] | None = None

    def _write(self, t, result) -> float:
        self.last = (t, result)
        return 0.0


class OmeTiffSink(Sink):
    """One frame's RI and the saved quantities as OME-TIFF files, written as one unit (a source
    of several frames is refused).

    Parameters
    ----------
    paths : dict of str to Path
        {quantity: file}, 'ri' included.
    meta : dict, optional
        Metadata stored with every file.
    """

    def __init__(self, paths: dict, meta: dict | None = None):
        if not isinstance(paths, dict) or "ri" not in paths:
            raise SsdpcError(f"OmeTiffSink takes {{quantity: file}} with 'ri', got {paths!r:.80}")
        self.paths, self.meta = dict(paths), dict(meta or {})
        self.save = [n for n in self.paths if n != "ri"]
        self.written: list[Path] = []
        self.result = None  # the frame's Result, once written

    def _open(self, job, grid, source) -> set[int]:
        if source.available() != 1 or not source.finished():
            raise SsdpcError(f"{source.name} holds several frames; write a time series to OME-Zarr (-o OUT.zarr)")
        return set()

    def _write(self, t, result) -> float:
        voxel = result.voxel_um
        meta = {**self.meta, "settings": result.settings, "z_um": result.z_um.tolist()}
        files = {
            self.paths[name]: (data, axes, voxel, {**meta, "quantity": what})
            for name, (data, axes, what) in result.images(self.save).items()
        }
        self.written = write_ome_tiffs(files)
        self.result = result
        return 0.0


class ZarrSink(Sink):
    """A resumable (t, z, y, x) OME-Zarr store, one chunk per frame (see :mod:`napari_ssdpc.io.store`).

    A rerun with the same input and job skips the frames marked done; one writer at a time (a lock
    beside the store); a frame is marked done only after all its chunks are written.

    Parameters
    ----------
    out : str or Path
        The ``.zarr`` folder.
    save : iterable of str
        Quantities beside RI.
    meta : dict, optional
        Metadata stored with every image.
    """

    def __init__(self, out, save=(), meta: dict | None = None):
        if not isinstance(out, (str, os.PathLike)):
            raise SsdpcError(f"ZarrSink takes the store's path (OUT.zarr), got {type(out).__name__}")
        self.out = Path(out)
        self.save = parse_save(list(save))
        self.meta = dict(meta or {})
        self._lock: StoreLock | None = None
        self._length = 0
        self._digits: int | None = None
        self._digits_checked = False
        self._live = None  # a live source, whose kept and dropped frames are recorded at the end
        self._stamp: dict | None = None
        if not self.out.parent.is_dir():
            raise SsdpcError(f"output folder does not exist: {self.out.parent} (create it first)")
        if self.out.exists() and not self.out.is_dir():
            raise SsdpcError(f"{self.out} exists and is a file, not an OME-Zarr folder; choose a new output path")

    def _open(self, job, grid, source) -> set[int]:
        n = source.available()
        ident = source.identity()
        growing = grows(source)  # a recording still being written, or a camera's frames: the store grows with them
        if not (growing or source.finished()):
            raise SsdpcError(f"{source.name}: a store needs the series' length; follow live frames into memory")
        layout = grid.layout(self.save)
        stamp = {
            "input": ident,
            "frames": None if growing else n,
            "frame_shape": list(source.frame_shape),
            "recipe": job.result_key,
            "outputs": sorted(layout),
            "store_digits": job.config.outputs.store_digits,
        }
        self._lock = StoreLock(self.out).__enter__()  # one writer per store
        attrs = {**self.meta, "settings": grid.settings}
        digits = self._digits = job.config.outputs.store_digits
        try:
            done = open_store(self.out, n, layout, grid.voxel_um, stamp, attrs, grid.origin_um, digits)
        except BaseException:  # refused or failed: the store is not written, the lock not kept
            self._close()
            raise
        self._length = int(done.shape[0])
        self._stamp = stamp_of(self.out)  # as stored (a resumed store keeps its own, updated by open_store)
        self._live = source if ident.get("live") else None
        return set(np.flatnonzero(done[:] == 1).tolist())

    def _accept(self, t, result) -> None:
        if self._stamp is None:  # a Dask worker's sink is not opened: the stamp is the store's
            self._stamp = stamp_of(self.out)
        check_input_unchanged(self._stamp, t)  # the frame was read from the recording the store names
        if self._digits is not None and not self._digits_checked:
            self._digits_checked = True
            _check_digits(self._digits, result.delta_n)

    def _write(self, t, result) -> float:
        if t >= self._length:  # a followed recording grew
            grow_store(self.out, t + 1)
            self._length = t + 1
        return write_frame(self.out, t, result.images(self.save))

    def _close(self) -> None:
        if self._lock is not None:
            try:
                if self._live is not None:  # the frames kept and dropped, also after a stop or an error
                    record_live_frames(self.out, self._live.summary())
            finally:
                self._live = None
                self._lock.__exit__(None, None, None)
                self._lock = None


def _check_digits(digits: int, delta_n) -> None:
    """Warn (once a run, on its first frame) when a store's digits cannot hold the sample's Δn to 1 %.

    Parameters
    ----------
    digits : int
        Decimal digits the store keeps of every value (errors up to 10^-digits).
    delta_n : ndarray
        The first frame's Δn.
    """
    peak = float(np.nanmax(np.abs(delta_n))) if np.size(delta_n) else 0.0
    step = 10.0**-digits
    if peak > 0 and step > 0.01 * peak:
        need = math.ceil(-math.log10(0.01 * peak))
        warnings.warn(
            f"--store-digits {digits} keeps values to {step:g}, {100 * step / peak:.0f} % of this sample's peak "
            f"|Δn| {peak:.2g}: its Δn is stored with errors that large; use --store-digits {need} or more, or "
            "leave it out (float32)",
            SsdpcWarning,
            stacklevel=2,
        )
