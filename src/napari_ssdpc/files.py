"""Safe file writes, used by every layer that writes a file.

- :func:`atomic_write`: one file appears complete or not at all. The data go to a hidden
  temporary file beside the target (``.NAME.PID.XXXX.part``), which is flushed to disk and then
  renamed over it, so an error or a kill never leaves a half-written file over a good one. A
  ``.part`` file left by a killed process (its PID no longer runs) is removed by the next write.
- :func:`atomic_write_set`: several files written as one unit: all temporaries first, each
  flushed to disk, then all renames, so a failure never leaves a new file beside an old one.
- :func:`os_error`: a file-system fault (full disk, read-only folder, ...) as a one-line
  :class:`~napari_ssdpc.errors.SsdpcError` that names the fix.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

from napari_ssdpc.errors import SsdpcError

__all__ = ["atomic_write", "atomic_write_set", "clean_stale_parts", "file_times", "os_error", "pid_alive"]

_PART = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[^.]+\.part$")


def file_times(path: str | Path) -> tuple[int, int, int]:
    """Bytes, latest modification and latest status change (ns) of a file, or of all the files of a
    folder (a store): what says whether an input changed, without reading it.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    (int, int, int)
        Size in bytes, ``st_mtime_ns`` and ``st_ctime_ns`` (the latest of the folder's files).
    """
    path = Path(path)
    files = [p for p in path.rglob("*") if p.is_file()] if path.is_dir() else [path]
    size = mtime = ctime = 0
    for p in files:
        st = p.stat()
        size, mtime, ctime = size + st.st_size, max(mtime, st.st_mtime_ns), max(ctime, st.st_ctime_ns)
    return size, mtime, ctime


def pid_alive(pid: int) -> bool:
    """Whether a process with this id runs on this machine.

    Parameters
    ----------
    pid : int
        Process id.

    Returns
    -------
    bool
    """
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it runs, under another user
        return True
    return True


def os_error(e: OSError, path: str | Path, doing: str = "writing") -> SsdpcError:
    """A one-line error for a file-system fault, naming the fix.

    Parameters
    ----------
    e : OSError
        The fault.
    path : str or Path
        The file or folder concerned.
    doing : str
        What was being done ("writing", "reading", "creating").

    Returns
    -------
    SsdpcError
    """
    fixes = {
        errno.ENOSPC: "disk full (no space left on the device); free some space or write to another disk",
        errno.EDQUOT: "disk quota exceeded; free some space or write to another disk",
        errno.EROFS: "the file system is read-only; choose a writable output folder",
        errno.EACCES: "permission denied; choose a folder you may write to",
        errno.EPERM: "permission denied; choose a folder you may write to",
        errno.EISDIR: "it is a folder; give a file path",
        errno.ENOTDIR: "a part of the path is a file, not a folder; check the path",
        errno.ENOENT: "the folder does not exist; create it first",
        errno.EEXIST: "it already exists; choose another path",
        errno.ENAMETOOLONG: "the name is too long; choose a shorter path",
    }
    code = e.errno
    if code is None and re.search(r"\d+ requested and \d+ written", str(e)):  # numpy's short write: a full disk
        code = errno.ENOSPC
    fix = fixes.get(code or 0, f"{e.strerror or e or type(e).__name__}; check the path and the disk")
    return SsdpcError(f"{doing} {path}: {fix}")


def clean_stale_parts(path: str | Path) -> list[Path]:
    """Remove the temporary files of ``path`` left by killed writers (their PID is gone).

    Parameters
    ----------
    path : str or Path
        The target file whose ``.NAME.PID.XXXX.part`` siblings are checked.

    Returns
    -------
    list of Path
        The files removed.
    """
    path = Path(path)
    removed: list[Path] = []
    try:
        siblings = list(path.parent.glob(f".{glob_escape(path.name)}.*.part"))
    except OSError:
        return removed
    for p in siblings:
        m = _PART.match(p.name)
        if m and m["name"] == path.name and not pid_alive(int(m["pid"])):
            with contextlib.suppress(OSError):
                p.unlink()
                removed.append(p)
    return removed


def glob_escape(name: str) -> str:
    """``name`` with the glob special characters escaped.

    Parameters
    ----------
    name : str
        A file name.

    Returns
    -------
    str
        A glob pattern that matches exactly ``name``.
    """
    return re.sub(r"([\[\]*?])", r"[\1]", name)


def _check_folder(path: Path) -> None:
    parent = path.parent
    if not parent.exists():
        raise SsdpcError(f"output folder does not exist: {parent} (create it first)")
    if not parent.is_dir():
        raise SsdpcError(f"output folder {parent} is a file; check the path")
    if path.is_dir():
        raise SsdpcError(f"output {path} is a folder; give a file path")


def _temp_for(path: Path) -> Path:
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".part", dir=path.parent)
    except OSError as e:
        raise os_error(e, path) from None
    os.close(fd)
    return Path(tmp)


def _finish(tmp: Path) -> None:
    """Give the temporary file the usual permissions and flush it to the disk."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600
    _fsync(tmp)


@contextlib.contextmanager
def atomic_write(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; move it over ``path`` only on success.

    Parameters
    ----------
    path : str or Path
        The file to write.

    Yields
    ------
    Path
        The temporary file to write to.

    Raises
    ------
    SsdpcError
        The folder is missing or not writable, the path is a folder, or the disk is full;
        ``path`` is then untouched.
    """
    with atomic_write_set([path]) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_write_set(paths: Sequence[str | Path]) -> Iterator[list[Path]]:
    """Write several files as one unit: all or none of them are replaced.

    Every file is written to its temporary file first; only when all are complete are they
    flushed to the disk and renamed over their targets, one after the other. An error while
    writing replaces none of the targets.

    Parameters
    ----------
    paths : sequence of str or Path
        The files to write (distinct).

    Yields
    ------
    list of Path
        One temporary file per target, in the same order.

    Raises
    ------
    SsdpcError
        As :func:`atomic_write`.
    """
    targets = [Path(p) for p in paths]
    for p in targets:
        _check_folder(p)
        clean_stale_parts(p)
    temps: list[Path] = []
    try:
        for p in targets:
            temps.append(_temp_for(p))
        try:
            yield temps
            for t in temps:
                _finish(t)
            for t, p in zip(temps, targets):
                os.replace(t, p)
            _fsync_folders(targets)
        except OSError as e:
            raise os_error(e, targets[0] if len(targets) == 1 else ", ".join(map(str, targets))) from None
    finally:
        for t in temps:
            with contextlib.suppress(OSError):
                if t.exists():
                    t.unlink()


def _fsync(path: str | Path) -> None:
    """Flush a written file to disk before it is renamed into place."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_folders(paths: Sequence[Path]) -> None:
    """Flush the renames (best effort: some file systems cannot sync a folder)."""
    for folder in {p.parent for p in paths}:
        with contextlib.suppress(OSError):
            fd = os.open(folder, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
