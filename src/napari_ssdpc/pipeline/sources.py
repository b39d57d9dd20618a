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
from typing import Protocol, runtime_checkable

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.frame_source import StoredFrames

__all__ = ["FrameSource", "LiveFrames", "as_source"]


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
    """Frames that arrive one by one (a camera, a writer thread) until :meth:`close`.

    Parameters
    ----------
    frame_shape : (int, int)
        (H, W) of every frame, px.
    name : str
        For messages.

    Examples
    --------
    >>> live = LiveFrames((512, 512))               # doctest: +SKIP
    >>> camera.on_frame(live.push)                   # each new frame enters the loop
    >>> pipeline.run(live, sink)                     # returns after live.close()
    """

    def __init__(self, frame_shape, name: str = "live frames"):
        self._shape = (int(frame_shape[0]), int(frame_shape[1]))
        self._name = name
        self._frames: list[np.ndarray] = []
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
        """Add a frame; returns its index.

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
            self._frames.append(a)
            self._added.notify_all()
            return len(self._frames) - 1

    def close(self) -> None:
        """No more frames: the loop ends after the ones pushed."""
        with self._added:
            self._closed = True
            self._added.notify_all()

    def available(self) -> int:
        """Frames pushed so far."""
        return len(self._frames)

    def finished(self) -> bool:
        """Closed."""
        return self._closed

    def wait(self, timeout_s: float) -> None:
        """Block until a frame is pushed, the source is closed, or ``timeout_s`` passed.

        Parameters
        ----------
        timeout_s : float
            Longest wait, s.
        """
        with self._added:
            n = len(self._frames)
            self._added.wait_for(lambda: self._closed or len(self._frames) > n, timeout=timeout_s)

    def __getitem__(self, t: int) -> np.ndarray:
        return self._frames[int(t)]

    def identity(self) -> dict:
        """A live source is not a recording: it cannot be resumed."""
        return {"path": self._name, "size": None, "mtime_ns": None, "frames": None, "sha256": None}
