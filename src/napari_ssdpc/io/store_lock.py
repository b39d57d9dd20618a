"""One writer per series store: ``.OUT.lock`` beside it, held with an OS lock (``flock``; on
Windows ``msvcrt.locking``); the PID written in it only names the holder in messages."""

from __future__ import annotations

import contextlib
import errno
import os
from pathlib import Path

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import os_error

__all__ = ["StoreLock"]


class StoreLock:
    """``.OUT.lock`` beside a store: one writer at a time, held by an OS lock; a context manager.

    The writer holds an exclusive ``flock`` on the lock file (``msvcrt.locking`` on Windows) for as
    long as it writes; the operating system releases it when the process ends, however it ends.
    Who holds the store is decided by that lock alone: the PID written into the file is only for
    the message, so an empty file (a writer between taking the lock and writing its PID) or a file
    left by a killed writer never reads as a free or a dead owner. After taking the lock, the file
    must still be the one at the path (a writer that finished removes it while holding it).

    Parameters
    ----------
    out : str or Path
        The store.
    """

    def __init__(self, out):
        out = Path(out)
        self.path = out.parent / f".{out.name}.lock"
        self.out = out
        self._fd: int | None = None

    def __enter__(self) -> StoreLock:
        if self._fd is not None:
            raise SsdpcError(f"{self.out}: this lock is held already; release it before taking it again")
        for _ in range(20):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o644)
            except OSError as e:
                raise os_error(e, self.out, "locking") from None
            try:
                held = _try_lock(fd)
            except OSError as e:  # a file system without locks
                os.close(fd)
                raise os_error(e, self.out, "locking") from None
            if not held:
                os.close(fd)
                pid = self._owner()
                who = f"process {pid}" if pid and pid != os.getpid() else "another process"
                raise SsdpcError(
                    f"{self.out} is being written by {who}; wait for it to finish, or stop it and rerun to resume"
                )
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # the previous writer removed the file we locked: lock the new one
                os.close(fd)
                continue
            try:
                os.ftruncate(fd, 0)
                os.write(fd, str(os.getpid()).encode())
            except OSError as e:
                os.close(fd)
                raise os_error(e, self.out, "locking") from None
            self._fd = fd
            return self
        raise SsdpcError(f"{self.out}: cannot take the lock {self.path}; remove it if no run is writing the store")

    def _owner(self) -> int | None:
        try:
            return int(self.path.read_text().strip() or 0) or None
        except (OSError, ValueError):
            return None

    def __exit__(self, *exc) -> None:
        if self._fd is None:
            return
        with contextlib.suppress(OSError):  # removed while held: no one can lock this file any more
            self.path.unlink()
        os.close(self._fd)  # releases the OS lock
        self._fd = None


def _try_lock(fd: int) -> bool:
    """Take an exclusive OS lock on an open file without waiting; False where another holds it."""
    try:
        import fcntl
    except ImportError:  # Windows
        import msvcrt

        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)  # type: ignore[attr-defined]
        except OSError:
            return False
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as e:
        if e.errno in (errno.EAGAIN, errno.EACCES):
            return False
        raise
    return True
