"""The samples' cache: frames simulated once, kept under the package version, found again by a hash
of everything that made them; and the background simulations that stop when napari exits."""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import json
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

from napari_ssdpc import __version__

__all__ = [
    "BACKGROUND",
    "EXITING",
    "SHIPPED",
    "Prefetch",
    "cache_dir",
    "cached",
    "key",
    "stop_background",
    "unless_exiting",
]

#: The frames that ship with the package.
SHIPPED = Path(__file__).parent / "data"
STALE_PART_S = 600.0  # an unfinished cache file older than this was left by an exit


def cache_dir() -> Path:
    """Where simulated sample frames are cached: ``$NAPARI_SSDPC_CACHE``/version (default ~/.cache/napari-ssdpc).

    Returns
    -------
    Path
    """
    root = os.environ.get("NAPARI_SSDPC_CACHE") or Path.home() / ".cache" / "napari-ssdpc"
    path = Path(root) / __version__
    path.mkdir(parents=True, exist_ok=True)
    for part in path.glob(".*.part"):  # a write that napari's exit cut short (background thread)
        with contextlib.suppress(OSError):
            if time.time() - part.stat().st_mtime > STALE_PART_S:
                part.unlink()
    return path


def key(*parts) -> str:
    """A short hash of everything that made a frame (its cache file's name carries it).

    Parameters
    ----------
    *parts
        JSON-able values (others by their repr).

    Returns
    -------
    str
        10 hex digits.
    """
    text = json.dumps(parts, sort_keys=True, default=repr)
    return hashlib.sha1(text.encode()).hexdigest()[:10]


#: Set when the interpreter exits: a background simulation stops within one source point (left
#: running, it was torn down inside an FFT and napari's exit aborted: "terminate called ...").
EXITING = threading.Event()
BACKGROUND: list[threading.Thread] = []


@atexit.register
def stop_background() -> None:
    """Stop the background simulations (at exit): set :data:`EXITING` and wait for their threads."""
    EXITING.set()
    for thread in BACKGROUND:
        thread.join(timeout=30.0)


def unless_exiting(done, total) -> None:
    """A simulation's progress callback that ends it when the interpreter exits.

    Parameters
    ----------
    done, total : int
        The simulation's progress (unused).
    """
    if EXITING.is_set():
        from napari_ssdpc.errors import Cancelled

        raise Cancelled("napari is closing")


_LOCKS: dict[Path, threading.Lock] = {}
_LOCKS_GUARD = threading.Lock()


def _file_lock(path: Path) -> threading.Lock:
    """One lock per cache file: two threads asking for one frame simulate it once."""
    with _LOCKS_GUARD:
        return _LOCKS.setdefault(path, threading.Lock())


def cached(name: str, make, key: str = "") -> np.ndarray:
    """Read ``name`` from the shipped frames or the cache, or make it and write it there (atomically).

    Parameters
    ----------
    name : str
        The frame's name.
    make : callable
        ``make()`` gives the frame, (H, W).
    key : str
        :func:`key` of what made it ('' for none).

    Returns
    -------
    ndarray, (H, W)
    """
    from napari_ssdpc.io.frames import read_frame, write_tiff

    path = cache_dir() / (f"{name}-{key}.tif" if key else f"{name}.tif")
    with _file_lock(path):
        for known in (SHIPPED / path.name, path):  # shipped with the package, else made here before
            if known.is_file():
                return read_frame(known, allow_series=False, name="sample frame")
        data = make()
        write_tiff(path, data, photometric="minisblack")
    return data


#: How much lower than the GUI a background simulation runs (a thread's nice value, Linux).
BACKGROUND_NICE = 10


def background_priority() -> None:
    """Lower the calling thread's scheduling priority (Linux: its nice value, per thread), so that
    napari's thread and the user's jobs go first on a busy machine; elsewhere nothing changes (a
    thread id there is no process id to renice)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), BACKGROUND_NICE)


class Prefetch:
    """Simulates (or reads from the cache) every frame of a series in a background thread that stops
    when napari exits (:func:`stop_background`).

    It works onward from the last frame read (:meth:`asked`), wrapping round, so that the frames
    after the one on screen are ready first; it stops when every frame is cached.

    Parameters
    ----------
    make : callable
        ``make(i)`` simulates or reads frame ``i`` (into the cache).
    n_frames : int
    """

    def __init__(self, make, n_frames: int):
        self.make = make
        self.n_frames = int(n_frames)
        self.made: set[int] = set()
        self._next = 0
        self._guard = threading.Lock()
        self.thread = threading.Thread(target=self._run, name="ssdpc series prefetch", daemon=True)
        BACKGROUND.append(self.thread)
        self.thread.start()

    def asked(self, i: int) -> None:
        """Frame ``i`` was read: go on from the frame after it.

        Parameters
        ----------
        i : int
            The frame read.
        """
        with self._guard:
            self._next = (int(i) + 1) % self.n_frames

    def _pick(self) -> int | None:
        with self._guard:
            order = [(self._next + k) % self.n_frames for k in range(self.n_frames)]
            return next((i for i in order if i not in self.made), None)

    def _run(self) -> None:
        background_priority()
        while not EXITING.is_set() and (i := self._pick()) is not None:
            try:
                self.make(i)
            except Exception:  # the frame is simulated again when it is read, and raises there
                return
            with self._guard:
                self.made.add(i)
