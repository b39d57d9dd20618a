"""Output paths checked before anything is computed or written.

:func:`check_outputs` compares every output (main files and sidecars) with every input after
resolving links and ``./``, refuses two outputs with one name, a sidecar that would replace a
file this program did not write (unless ``overwrite``), a missing or read-only folder, and an
output that is a folder. It runs before the first byte is written, so a refused run leaves the
disk as it was.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

from napari_ssdpc.errors import SsdpcError

__all__ = ["check_outputs", "is_ours", "same_file", "writable_folder"]


def _resolved(path: str | Path) -> Path:
    return Path(os.path.abspath(Path(path).expanduser())).resolve()


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name the same file (links, ``./`` and hard links count).

    Parameters
    ----------
    a, b : str or Path

    Returns
    -------
    bool
    """
    if _resolved(a) == _resolved(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def writable_folder(folder: str | Path, what: str = "output folder") -> Path:
    """Check that a folder exists and may be written to.

    Parameters
    ----------
    folder : str or Path
    what : str
        Its role, for the message.

    Returns
    -------
    Path

    Raises
    ------
    SsdpcError
        Missing, not a folder, or not writable.
    """
    folder = Path(folder)
    if not folder.exists():
        raise SsdpcError(f"{what} does not exist: {folder} (create it first)")
    if not folder.is_dir():
        raise SsdpcError(f"{what} {folder} is a file, not a folder; check the path")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise SsdpcError(f"{what} {folder} is not writable (read-only or no permission); choose another folder")
    return folder


def is_ours(path: str | Path) -> bool:
    """Whether an existing file was written by napari-ssdpc (a result, calibration or its overlay).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    bool
    """
    path = Path(path)
    try:
        if path.suffix == ".json":
            return json.loads(path.read_text(encoding="utf-8")).get("format", "").startswith("napari-ssdpc")
        if path.name.endswith((".tif", ".tiff")):
            from napari_ssdpc.io.frames import tiff_info

            info = tiff_info(path)
            return "napari-ssdpc" in f"{info.description} {info.software}"
        if path.suffix == ".png":  # our figures carry a Software text chunk
            from PIL import Image

            with Image.open(path) as im:
                return str(im.info.get("Software", "")).startswith("napari-ssdpc")
    except Exception:  # unreadable or foreign: not ours
        return False
    return False


def check_outputs(
    outputs: Mapping[str, str | Path],
    inputs: Mapping[str, str | Path | None],
    *,
    overwrite: bool = False,
    replaceable: Callable[[Path], bool] = is_ours,
    folders: Iterable[str] = (),
) -> dict[str, Path]:
    """Refuse any output that would destroy an input, another output or a foreign file.

    Parameters
    ----------
    outputs : mapping of str to path
        Role -> output path, e.g. ``{"calibration": "cal.json", "overlay": "cal.png"}``.
    inputs : mapping of str to path or None
        Role -> input path (None: not given).
    overwrite : bool
        Replace existing files whatever they hold; otherwise an existing output file is replaced
        only when ``replaceable(path)`` (a file napari-ssdpc wrote).
    replaceable : callable
        ``replaceable(path) -> bool`` for an existing output file.
    folders : iterable of str
        Roles in ``outputs`` that are folders (a store or a demo folder) rather than files.

    Returns
    -------
    dict of str to Path
        The outputs as paths.

    Raises
    ------
    SsdpcError
        The first conflict, naming both paths and the fix.
    """
    outs = {role: Path(p) for role, p in outputs.items()}
    folders = set(folders)
    roles = list(outs)
    for i, a in enumerate(roles):
        for b in roles[i + 1 :]:
            if _resolved(outs[a]) == _resolved(outs[b]):
                raise SsdpcError(
                    f"the {b} would be written over the {a} ({outs[a]}); give the {a} another name "
                    f"(e.g. {outs[a].with_suffix('').name}{_default_suffix(a, outs[a])})"
                )
    for role, out in outs.items():
        for what, src in inputs.items():
            if src is not None and (same_file(out, src) or _inside(src, out, role in folders)):
                raise SsdpcError(f"the {role} {out} would overwrite the {what} {src}; write the {role} to another path")
        writable_folder(out.parent if str(out.parent) else Path("."))
        if role in folders:
            if out.exists() and not out.is_dir():
                raise SsdpcError(f"{role} {out} exists and is a file, not a folder; choose a new path")
            continue
        if out.is_dir():
            raise SsdpcError(f"{role} {out} is a folder; give a file path")
        if out.exists() and not out.is_file():  # /dev/full, a pipe: never read, never replaced
            raise SsdpcError(f"{role} {out} is not a regular file (a device or a pipe); give a file path")
        if out.exists() and not overwrite and not replaceable(out):
            raise SsdpcError(
                f"the {role} {out} would replace a file napari-ssdpc did not write; move it away, "
                "choose another output name or pass --overwrite"
            )
    return outs


def _inside(src: str | Path, folder: Path, is_folder: bool) -> bool:
    """An input inside an output folder (a store or a demo folder that is rewritten)."""
    if not is_folder:
        return False
    s, f = _resolved(src), _resolved(folder)
    return f in s.parents


def _default_suffix(role: str, path: Path) -> str:
    return {"calibration": ".json", "overlay": ".png"}.get(role, path.suffix or "")
