"""A recording still being written, read frame by frame as it grows (``ssdpc reconstruct --follow``).

Three kinds of recording are followed: a TIFF whose pages are appended (one page per frame), a
(t, y, x) OME-Zarr image whose t axis grows, and a folder whose TIFF files (one frame each, in
natural name order) keep arriving. A frame counts as arrived when a later one exists, or when
the recording has not changed for ``settle_s`` (a writer finishing the last frame). The
recording counts as finished once no frame has arrived for ``idle_s``.

The identity of a followed recording is its path, frame shape and data type and the SHA-256 of
its first frame: a store resumed from a later run checks that it still follows the same
recording, whatever has been appended since.
"""

from __future__ import annotations

import hashlib
import re
import threading
import time
import warnings
from pathlib import Path

import numpy as np

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.io.frames import complete_pages

__all__ = ["FollowedFrames", "kind_of_recording"]

#: How often the recording is looked at while waiting, s.
POLL_S = 0.2
_TIFF = (".tif", ".tiff")


def kind_of_recording(path: Path) -> str:
    """'tiff', 'zarr' or 'folder' (of TIFF files), from what ``path`` is.

    Parameters
    ----------
    path : Path

    Returns
    -------
    str
    """
    if path.is_file():
        if path.suffix.lower() not in _TIFF:
            raise SsdpcError(f"{path}: --follow reads a TIFF, an OME-Zarr image or a folder of TIFF files")
        return "tiff"
    if path.is_dir():
        if any((path / n).exists() for n in (".zgroup", ".zarray", "zarr.json")):
            return "zarr"
        return "folder"
    raise SsdpcError(f"{path} does not exist; start the recording first, or give the path it will be written to")


def _natural_key(name: str):
    return [int(p) if p.isdigit() else p.lower() for p in re.split(r"(\d+)", name)]


class FollowedFrames:
    """Frames of a recording that is still being written (a :class:`~napari_ssdpc.pipeline.sources.FrameSource`).

    Parameters
    ----------
    path : str or Path
        A TIFF, an OME-Zarr image or a folder of TIFF files.
    idle_s : float
        The recording is finished once no frame has arrived for this long, s.
    settle_s : float
        The newest frame counts as arrived once the recording has not changed for this long, s.
    first_wait_s : float, optional
        How long to wait for the recording and its first frame, s (default ``idle_s``).
    should_stop : callable, optional
        Checked while waiting for the first frame.

    Attributes
    ----------
    arrived_at : dict of int to float
        ``time.time()`` at which each frame was first seen complete (for the latency).
    """

    def __init__(self, path, *, idle_s: float = 30.0, settle_s: float = 1.0, first_wait_s=None, should_stop=None):
        self.path = Path(path)
        wait_s = float(idle_s) if first_wait_s is None else float(first_wait_s)
        deadline = time.monotonic() + wait_s
        while not self.path.exists():  # the camera has not started yet: wait for it, as for its frames
            if time.monotonic() > deadline or (should_stop is not None and should_stop()):
                raise SsdpcError(
                    f"{self.path} does not exist and did not appear within {wait_s:g} s; start the recording, "
                    "or wait longer with --idle SECONDS"
                )
            time.sleep(POLL_S)
        self.kind = kind_of_recording(self.path)
        self.idle_s, self.settle_s = float(idle_s), float(settle_s)
        self.arrived_at: dict[int, float] = {}
        self._lock = threading.Lock()
        self._count, self._ready, self._files, self._gaps_named = 0, 0, [], set()
        self._signature, self._changed = None, time.monotonic()
        self._pages = 0  # complete pages of a TIFF at its last signature
        self._last_arrival = time.monotonic()
        self._names: list[str] = []  # a folder's file of each frame that has arrived
        self._complete = 0  # a folder's leading files that hold a whole TIFF frame
        self._checked: dict[str, tuple] = {}  # a folder's file -> (size, mtime) at which it was complete
        self._first_hash: str | None = None
        self._verified = None  # the signature at which frame 0 was last found unchanged
        while self._scan() == 0:
            if time.monotonic() > deadline or (should_stop is not None and should_stop()):
                raise SsdpcError(
                    f"{self.path}: no complete frame arrived within {wait_s:g} s; start the recording, or "
                    "wait longer with --idle SECONDS"
                )
            time.sleep(POLL_S)
        first = self[0]
        if first.ndim != 2:
            raise SsdpcError(f"{self.path}: frame 0 has shape {first.shape}; expected one 2D frame per page or file")
        self._shape, self._dtype = tuple(int(v) for v in first.shape), first.dtype
        self._first_hash = _hash(first)
        self._verified = self._signature

    # ---------------------------------------------------------------- the protocol
    @property
    def name(self) -> str:
        """The recording's absolute path."""
        return str(self.path.resolve())

    @property
    def frame_shape(self) -> tuple[int, int]:
        """(H, W) of frame 0, px."""
        return self._shape

    def available(self) -> int:
        """Frames that have arrived completely."""
        return self._scan()

    def finished(self) -> bool:
        """No frame has arrived for ``idle_s`` and none is being written.

        Raises
        ------
        SsdpcError
            A folder's file stayed empty or incomplete for ``idle_s`` (named, with its frame). The
            frame loop asks only once it has taken every frame that arrived.
        """
        self._scan()
        idle = time.monotonic() - self._last_arrival > self.idle_s
        if idle and self.kind == "folder" and self._complete < self._count:
            name = self._files[self._complete].name
            raise SsdpcError(
                f"{self.path}: {name} (frame {self._complete}) is empty or incomplete and did not change for "
                f"{self.idle_s:g} s; the frames before it are kept; complete or remove it, then follow again"
            )
        return self._count == self._ready and idle

    def wait(self, timeout_s: float) -> None:
        """Look again after ``timeout_s`` (at most :data:`POLL_S`).

        Parameters
        ----------
        timeout_s : float
            Longest wait, s.
        """
        time.sleep(max(0.0, min(float(timeout_s), POLL_S)))
        self._scan()

    def identity(self) -> dict:
        """Path, frame shape, data type and the SHA-256 of frame 0 (the rest is still growing)."""
        return {
            "path": self.name,
            "followed": True,
            "frame_shape": list(self._shape),
            "dtype": str(self._dtype),
            "sha256": self._first_hash,
        }

    def __getitem__(self, t) -> np.ndarray:
        t = int(t)
        if not 0 <= t < max(self._ready, 1):
            raise IndexError(f"frame {t} of {self._ready} arrived")
        try:
            frame = self._read(t)
            if t > 0:
                self._verify(t)
        except SsdpcError:
            raise
        except Exception as e:  # a writer between its steps, a damaged page
            raise SsdpcError(
                f"{self.path}: frame {t} cannot be read ({type(e).__name__}); check the recording"
            ) from None
        return np.array(frame, copy=True)

    def _verify(self, t: int) -> None:
        """Frame 0 is still the one the run started with (checked once per change of the recording,
        after frame ``t`` was read): a recording rewritten at the same path is never mixed in."""
        signature = self._signature
        if self._first_hash is None or signature == self._verified:
            return
        if _hash(self._read(0)) != self._first_hash:
            raise SsdpcError(
                f"{self.path}: frame 0 changed while frame {t} was read: another recording is being written at "
                "this path; the frames before it are kept; follow the new recording into a new output"
            )
        self._verified = signature

    # ---------------------------------------------------------------- the recording
    def _scan(self) -> int:
        """Count the frames present, and how many of them have arrived completely."""
        with self._lock:
            count, signature = self._look()
            if count < self._count:
                raise SsdpcError(
                    f"{self.path}: the recording shrank from {self._count} to {count} frames during the run "
                    "(rewritten or truncated); the frames before are kept; follow the new recording into a new output"
                )
            now = time.monotonic()
            if signature != self._signature:
                self._signature, self._changed = signature, now
            settled = now - self._changed >= self.settle_s
            ready = count if settled else max(count - 1, 0)
            if self.kind == "folder":  # a file still empty or half written is waited for
                ready = min(ready, self._complete)
                self._keep_order(ready)
            if ready > self._ready:
                stamp = time.time()
                for t in range(self._ready, ready):
                    self.arrived_at[t] = stamp
                self._ready, self._last_arrival = ready, now
            self._count = count
            return self._ready

    def _look(self) -> tuple[int, tuple]:
        """(frames present, a signature that changes whenever the recording does)."""
        if self.kind == "tiff":
            st = self.path.stat()
            signature = (st.st_size, st.st_mtime_ns)
            if signature != self._signature:  # the pages are parsed again only when the file changed
                pages = self._tiff_pages(st.st_size)
                if pages is None:  # a header being written: nothing new readable yet
                    return self._pages, self._signature
                self._pages = pages
            return self._pages, signature
        if self.kind == "zarr":
            array = self._zarr()
            entries = _entries(self._level_dir)
            newest = max((e.stat().st_mtime_ns for e in entries), default=0)
            count = _written_frames(array, entries, self._level_dir) if array.ndim == 3 else 1
            return count, (tuple(array.shape), count, newest)
        files = sorted(
            (p for p in self.path.iterdir() if p.suffix.lower() in _TIFF), key=lambda p: _natural_key(p.name)
        )
        self._files = files
        self._name_gaps(files)
        self._complete = self._ready + self._leading_complete(files[self._ready :])
        last = files[-1].stat() if files else None
        return len(files), (len(files), None if last is None else (last.st_size, last.st_mtime_ns))

    def _tiff_pages(self, size: int) -> int | None:
        """Pages whose data lie wholly within the file; None while it cannot be parsed."""
        import tifffile

        try:
            with tifffile.TiffFile(self.path) as tif:
                return complete_pages(tif.pages, size)
        except Exception:  # a header being written
            return None

    def _zarr(self):
        import zarr

        node = zarr.open(str(self.path), mode="r")
        level = "0"
        if not hasattr(node, "shape"):
            level = node.attrs.get("multiscales", [{}])[0].get("datasets", [{"path": "0"}])[0]["path"]
            node = node[level]
        self._level_dir = self.path / level if level else self.path
        return node

    def _leading_complete(self, files) -> int:
        """How many of ``files`` in a row hold a whole TIFF frame (each file parsed once per change)."""
        import tifffile

        n = 0
        for p in files:
            try:
                st = p.stat()
            except OSError:  # removed between the listing and now
                break
            key = (st.st_size, st.st_mtime_ns)
            if self._checked.get(p.name) != key:
                try:
                    with tifffile.TiffFile(p) as tif:
                        whole = st.st_size > 0 and complete_pages(tif.pages[:1], st.st_size) == 1
                except Exception:  # empty, or a header being written
                    whole = False
                if not whole:
                    break
                self._checked[p.name] = key
            n += 1
        return n

    def _read(self, t: int) -> np.ndarray:
        import tifffile

        if self.kind == "tiff":
            with tifffile.TiffFile(self.path) as tif:
                return tif.pages[t].asarray()
        if self.kind == "zarr":
            array = self._zarr()
            return np.asarray(array[t] if array.ndim == 3 else array[...]).squeeze()
        return tifffile.imread(self._files[t])

    def _keep_order(self, ready: int) -> None:
        """The files of the frames that have arrived keep their places: a file that arrives late with
        a lower number, or one deleted, would shift every later frame's index."""
        names = [p.name for p in self._files]
        for t, (was, now) in enumerate(zip(self._names, names, strict=False)):
            if was != now:
                raise SsdpcError(
                    f"{self.path}: frame {t} was {was} and is now {now} (a file arrived late with a lower "
                    "number, or one was deleted); the frames before are kept; number the files in the order "
                    "they are written, and follow into a new output"
                )
        if len(names) < len(self._names):
            raise SsdpcError(
                f"{self.path}: {self._names[len(names)]} (frame {len(names)}) was deleted during the run; the "
                "frames before are kept; follow into a new output"
            )
        self._names = names[: max(ready, len(self._names))]

    def _name_gaps(self, files) -> None:
        """Warn once per gap in a numbered sequence of files (a frame lost by the writer)."""
        numbers = [int(m.group(1)) for p in files if (m := re.search(r"(\d+)(?=\D*$)", p.stem))]
        if len(numbers) != len(files) or len(numbers) < 2:
            return
        for a, b in zip(numbers, numbers[1:]):
            if b > a + 1 and (a, b) not in self._gaps_named:
                self._gaps_named.add((a, b))
                missing = f"{a + 1}" if b == a + 2 else f"{a + 1}-{b - 1}"
                warnings.warn(
                    f"{self.path}: file number {missing} is missing between {a} and {b}; the frames are "
                    "reconstructed in file order, so frame indices after the gap are one per file present",
                    SsdpcWarning,
                    stacklevel=2,
                )


def _written_frames(array, entries, level_dir: Path) -> int:
    """Frames of a (t, y, x) zarr image whose chunks are on disk, from frame 0 on without a gap (its
    metadata may announce more than were written: a writer ahead of its data, or a damaged claim)."""
    names = [e.name for e in entries]
    if (level_dir / "c").is_dir():  # zarr v3 keys: c/t/y/x
        names = [e.name for e in _entries(level_dir / "c")]
    starts = {int(head) for n in names if (head := n.split(".")[0]).isdigit()}
    chunks = 0
    while chunks in starts:
        chunks += 1
    return min(int(array.shape[0]), chunks * int(array.chunks[0]))


def _hash(frame) -> str:
    """SHA-256 of a frame's values."""
    return hashlib.sha256(np.ascontiguousarray(frame).tobytes()).hexdigest()


def _entries(folder: Path):
    try:
        return list(Path(folder).iterdir())
    except OSError:
        return []
