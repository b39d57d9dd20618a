"""Frame sources: what the frame loop reads, whether the frames are all there or still arriving.

A source gives frames by index, says how many can be read now (:meth:`FrameSource.available`)
and whether more will come (:meth:`FrameSource.finished`), and names what it holds
(:meth:`FrameSource.identity`, the resume stamp of a series store). Files and arrays are
finished from the start (a TIFF path, an OME-Zarr image, a NumPy or a dask array, read one
frame at a time by :class:`~napari_ssdpc.io.frame_source.StoredFrames`); :class:`LiveFrames`
takes frames as they arrive (a camera callback, a writer) until it is closed.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol, runtime_checkable

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.frame_source import StoredFrames

__all__ = ["FrameSource", "LiveFrames", "as_source", "grows"]


@runtime_checkable
class FrameSource(Protocol):
    """What the frame loop needs of a source of raw frames (y, x), camera units."""

    @property
    def name(self) -> str:
        """For messages: a path, or 'array'."""

    @property
    def frame_shape(self) -> tuple[int, int]:
        """(H, W) of a frame, px."""

    def available(self) -> int:
        """Frames that can be read now (0 .. available-1)."""

    def finished(self) -> bool:
        """No frame will be added: the loop ends after the available ones."""

    def wait(self, timeout_s: float) -> None:
        """Block until a frame is added, the source is finished, or ``timeout_s`` passed.

        Parameters
        ----------
        timeout_s : float
            Longest wait, s.
        """

    def __getitem__(self, t: int) -> np.ndarray:
        """Frame ``t`` (y, x)."""

    def identity(self) -> dict:
        """What the frames are (path, size, SHA-256, ...), for the resume stamp."""


def grows(source) -> bool:
    """Whether a source's frames are still coming (a followed recording, a camera): its length is
    not known, and it is asked whether it has finished only once its frames are taken.

    Parameters
    ----------
    source : FrameSource

    Returns
    -------
    bool
    """
    ident = source.identity()
    return bool(ident.get("followed") or ident.get("live"))


def as_source(frames) -> FrameSource:
    """A frame source for a path (TIFF), a NumPy or dask array (t, y, x) or (y, x), or a source.

    Parameters
    ----------
    frames : FrameSource, str, Path or array

    Returns
    -------
    FrameSource
    """
    if isinstance(frames, FrameSource):
        return frames
    return StoredFrames(frames)


class LiveFrames:
    """Frames that arrive one by one (a camera, a writer thread) until :meth:`close`, in a bounded queue.

    The frames wait for the loop in a queue of at most ``maxsize``: when the solver lags, the oldest
    waiting frame is dropped (and counted: :meth:`dropped`), so the memory held stays that of
    ``maxsize`` + 1 frames however long the run, and :meth:`push` never blocks the camera. A frame
    is released once the loop asks for a later one.

    Parameters
    ----------
    frame_shape : (int, int)
        (H, W) of every frame, px.
    name : str
        For messages.
    maxsize : int or None
        Most frames waiting (≥ 1); None keeps every frame (a recording that must be complete).

    Examples
    --------
    >>> live = LiveFrames((512, 512))               # doctest: +SKIP
    >>> camera.on_frame(live.push)                   # each new frame enters the loop
    >>> report = pipeline.run(live, sink)            # returns after live.close()
    >>> report.dropped                               # the frames the solver could not keep up with
    """

    def __init__(self, frame_shape, name: str = "live frames", maxsize: int | None = 2):
        if maxsize is not None and not (isinstance(maxsize, int) and maxsize >= 1):
            raise SsdpcError(f"{name}: maxsize = {maxsize!r}; give a number of frames >= 1, or None to keep all")
        self._shape = (int(frame_shape[0]), int(frame_shape[1]))
        self._name = name
        self._maxsize = maxsize
        self._frames: dict[int, np.ndarray] = {}
        self._arrived: dict[int, float] = {}  # time.perf_counter() at each held frame's push, s
        self._count = 0
        self._claimed = -1
        self._dropped: list[int] = []
        self._closed = False
        self._added = threading.Condition()

    @property
    def name(self) -> str:
        """For messages."""
        return self._name

    @property
    def frame_shape(self) -> tuple[int, int]:
        """(H, W) of a frame, px."""
        return self._shape

    def push(self, frame) -> int:
        """Add a frame (dropping the oldest waiting one when the queue is full); returns its index.

        Parameters
        ----------
        frame : array_like, (H, W)
            Camera units.

        Returns
        -------
        int
        """
        a = np.array(frame, copy=True)
        if a.shape != self._shape:
            raise SsdpcError(f"{self._name}: a frame of shape {a.shape} in a source of {self._shape} frames")
        with self._added:
            if self._closed:
                raise SsdpcError(f"{self._name} is closed: no frame can be added")
            t = self._count
            self._frames[t], self._arrived[t] = a, time.perf_counter()
            self._count += 1
            if self._maxsize is not None:
                waiting = sorted(k for k in self._frames if k > self._claimed)
                for k in waiting[: max(len(waiting) - self._maxsize, 0)]:
                    del self._frames[k], self._arrived[k]
                    self._dropped.append(k)
            self._added.notify_all()
            return t

    def close(self) -> None:
        """No more frames: the loop ends after the ones pushed."""
        with self._added:
            self._closed = True
            self._added.notify_all()

    def available(self) -> int:
        """Frames pushed so far (dropped ones included: indices are the camera's)."""
        return self._count

    def finished(self) -> bool:
        """Closed."""
        return self._closed

    def claim(self, t: int) -> bool:
        """Keep frame ``t`` for the loop (it can no longer be dropped) and release the earlier ones.

        Parameters
        ----------
        t : int

        Returns
        -------
        bool
            False when frame ``t`` was dropped before the loop came to it.
        """
        with self._added:
            for k in [k for k in self._frames if k < t]:
                del self._frames[k], self._arrived[k]
            self._claimed = max(self._claimed, int(t))
            return int(t) in self._frames

    def dropped(self) -> list[int]:
        """Indices of the frames dropped so far, in order."""
        with self._added:
            return sorted(self._dropped)

    def arrived_at(self, t: int) -> float | None:
        """When frame ``t`` was pushed (``time.perf_counter()``, s), while it is held; else None.

        Parameters
        ----------
        t : int

        Returns
        -------
        float or None
        """
        with self._added:
            return self._arrived.get(int(t))

    def held(self) -> int:
        """Frames in memory now."""
        return len(self._frames)

    def wait(self, timeout_s: float) -> None:
        """Block until a frame is pushed, the source is closed, or ``timeout_s`` passed.

        Parameters
        ----------
        timeout_s : float
            Longest wait, s.
        """
        with self._added:
            n = self._count
            self._added.wait_for(lambda: self._closed or self._count > n, timeout=timeout_s)

    def __getitem__(self, t: int) -> np.ndarray:
        with self._added:
            if int(t) not in self._frames:
                raise SsdpcError(f"{self._name}: frame {t} was dropped (the queue holds {self._maxsize})")
            return self._frames[int(t)]

    def identity(self) -> dict:
        """A live source is not a recording: it cannot be resumed (``live``: a store is written anew)."""
        return {"path": self._name, "size": None, "mtime_ns": None, "frames": None, "sha256": None, "live": True}

    def summary(self) -> dict:
        """The frames kept and dropped so far, for the metadata of what the run writes.

        Returns
        -------
        dict
            ``frames`` (pushed), ``dropped`` (their indices) and ``maxsize`` (the queue's bound, None: all kept).
        """
        with self._added:
            return {"frames": self._count, "dropped": sorted(self._dropped), "maxsize": self._maxsize}
