"""The OME-Zarr store of a time series: creation, stamp, lock, resume, completeness.

- A new store is built in a hidden folder beside the target (``.OUT.PID.new``) with all its
  metadata, its stamp and its ``ssdpc_done`` array, and renamed into place: a kill during
  creation leaves only that hidden folder, which the next run removes.
- The stamp names what the store holds: the input's identity (path, size, modification time
  and SHA-256 of its content), the frame count and shape, the recipe and the outputs. A rerun
  resumes only the same job, and refuses a changed input naming both recordings.
- One writer at a time: the writer holds an OS lock (``flock``) on ``.OUT.lock`` beside the store,
  released by the system when the process ends; a lock file left by a killed writer is taken over.
- A frame is complete when its byte in ``ssdpc_done`` is 1 (set after all its chunks);
  :func:`read_complete` shows the other frames as NaN.
- A folder that is not a store of ours is refused before anything is written into it.
"""

from __future__ import annotations

import datetime
import os
import shutil
from pathlib import Path

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import file_times, glob_escape, os_error, pid_alive

__all__ = [
    "DONE",
    "STAMP",
    "check_input_unchanged",
    "done_frames",
    "grow_store",
    "mask_incomplete",
    "open_store",
    "read_complete",
    "stamp_of",
    "write_frame",
]

DONE = "ssdpc_done"  # root array: 1 where a frame is completely written
STAMP = "ssdpc_series"  # root attribute: what the store holds (input, settings, outputs)
_METADATA = {".zgroup", ".zattrs", ".zarray", "zarr.json"}


def _describe_input(ident) -> str:
    if not isinstance(ident, dict):
        return f"{ident} (no content hash)"
    when = ""
    if ident.get("mtime_ns"):
        when = ", modified " + datetime.datetime.fromtimestamp(ident["mtime_ns"] / 1e9).isoformat(timespec="seconds")
    size = f", {ident['size']} bytes" if ident.get("size") is not None else ""
    return (
        f"{ident.get('path')} ({ident.get('frames', '?')} frames{size}{when}, sha256 {ident.get('sha256', '?')[:12]})"
    )


def stamp_of(out):
    """The stamp (:data:`STAMP`) of an existing store, or None when the folder holds no store of ours.

    Parameters
    ----------
    out : str or Path

    Returns
    -------
    dict or None
    """
    import zarr

    try:
        return zarr.open_group(str(out), mode="r").attrs.get(STAMP)
    except Exception:  # not a zarr group at all
        return None


def _killed_creation(out: Path) -> bool:
    """Only zarr metadata and temporary chunk files: a store whose creation was killed."""
    return all(p.is_file() and (p.name in _METADATA or p.name.endswith(".partial")) for p in out.iterdir())


def _check_resume(out: Path, old: dict, stamp: dict) -> None:
    new_in, old_in = stamp["input"], old.get("input")
    if new_in.get("live"):  # a camera's frames are not a recording: nothing to resume, no frame to mix
        raise SsdpcError(
            f"{out} already holds a reconstruction; a live acquisition writes a new store: choose a new output "
            f"path, or delete {out}"
        )
    same = isinstance(old_in, dict) and old_in.get("sha256") == new_in.get("sha256")
    if not same:
        raise SsdpcError(
            f"{out} holds frames of another recording: it was made from {_describe_input(old_in)}, the input is "
            f"now {_describe_input(new_in)}; write to a new output path, or delete {out} to start over"
        )
    rest = {k: v for k, v in stamp.items() if k != "input"}
    differ = [k for k in rest if old.get(k) != rest[k]]
    if differ:
        words = {"recipe": "settings", "store_digits": "store digits", "frame_shape": "frame size"}
        raise SsdpcError(
            f"{out} holds a reconstruction with other {', '.join(words.get(k, k) for k in differ)}; choose a new "
            "output path or delete the old one to start over"
        )


def _create(out: Path, n_frames, layout, voxel, stamp: dict, attrs: dict, origin_um=None, digits=None) -> None:
    """Build the complete empty store in a hidden folder and rename it into place."""
    import zarr

    from napari_ssdpc.io.ome_zarr import create_ome_zarr

    for old in out.parent.glob(f".{glob_escape(out.name)}.*.new"):  # left by a killed creation
        pid = old.name[len(out.name) + 2 : -len(".new")]
        if pid.isdigit() and not pid_alive(int(pid)):
            shutil.rmtree(old, ignore_errors=True)
    tmp = out.parent / f".{out.name}.{os.getpid()}.new"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        root = zarr.open_group(str(tmp), mode="w", zarr_format=2)
        root.attrs[STAMP] = stamp
        for name, (shape, axes, what) in layout.items():
            create_ome_zarr(
                tmp,
                name,
                (n_frames,) + tuple(shape),
                "T" + axes,
                voxel,
                attrs={**attrs, "quantity": what},
                origin_um=origin_um,
                digits=digits,
            )
        root.create_array(DONE, shape=(n_frames,), chunks=(1,), dtype="uint8", fill_value=0)
        if out.exists():  # an empty folder, or one left by a killed creation
            for p in out.iterdir():
                p.unlink()
        os.replace(tmp, out)
    except OSError as e:
        raise os_error(e, out, "creating") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def open_store(out, n_frames: int, layout: dict, voxel, stamp: dict, attrs: dict, origin_um=None, digits=None):
    """Create the store, or reopen it to resume the same job. Returns the done-flags array.

    Parameters
    ----------
    out : str or Path
        The ``.zarr`` folder.
    n_frames : int
        Frames of the series.
    layout : dict
        ``{name: (shape per frame, axes, description)}`` (``outputs.layout``).
    voxel : tuple of float
        (dz, dy, dx), µm.
    stamp : dict
        What the store holds; its ``input`` is the input's identity (path, size, mtime_ns, sha256).
    attrs : dict
        Metadata stored with every image group.
    origin_um : tuple of float, optional
        (z, y, x) position of voxel 0, µm: the NGFF translation of every image.
    digits : int, optional
        Decimal digits a new store keeps of every value (see ``create_ome_zarr``); None: exact.

    Returns
    -------
    zarr.Array
        ``ssdpc_done``: 1 where a frame is complete.
    """
    import zarr

    from napari_ssdpc.io.ome_zarr import create_ome_zarr

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise SsdpcError(f"{out} exists and is a file, not an OME-Zarr folder; choose a new output path")
    old = stamp_of(out) if out.exists() else None
    if old is None:
        if out.exists() and any(out.iterdir()) and not _killed_creation(out):
            raise SsdpcError(f"{out} exists and was not written by `ssdpc reconstruct`; choose a new output path")
        _create(out, n_frames, layout, voxel, stamp, attrs, origin_um, digits)
    else:
        _check_resume(out, old, stamp)
    root = zarr.open_group(str(out), mode="r+", zarr_format=2)
    try:
        if old is not None and old.get("input") != stamp["input"]:  # the same content, touched or copied
            root.attrs[STAMP] = {**old, "input": stamp["input"]}  # the size and time each frame is checked against
        for name, (shape, axes, _) in layout.items():
            if not (name in root and "0" in root[name]):  # a store of an older version, half made
                shape_t = (n_frames,) + tuple(shape)
                create_ome_zarr(
                    out, name, shape_t, "T" + axes, voxel, overwrite=True, origin_um=origin_um, digits=digits
                )
        if DONE not in root:
            root.create_array(DONE, shape=(n_frames,), chunks=(1,), dtype="uint8", fill_value=0)
        for p in out.rglob("*.partial"):  # a temporary chunk file of a killed run
            p.unlink(missing_ok=True)
    except OSError as e:
        raise os_error(e, out) from None
    return root[DONE]


def write_frame(out, t: int, images: dict) -> float:
    """Write one frame's images into the store, then mark the frame done (the caller has checked
    the frame: :func:`check_input_unchanged`).

    Parameters
    ----------
    out : str or Path
        The store (made by :func:`open_store`).
    t : int
        Frame index.
    images : dict
        {name: (array, axes, description)} of one frame, as ``Result.images`` gives them.

    Returns
    -------
    float
        Seconds spent writing.
    """
    import time

    import zarr

    t0 = time.perf_counter()
    try:
        root = zarr.open_group(str(out), mode="r+")
        for name, (data, _, _) in images.items():
            root[name]["0"][t] = data
        root[DONE][t] = 1  # only after every chunk of the frame is on disk
    except OSError as e:
        raise os_error(e, Path(out)) from None
    return time.perf_counter() - t0


def check_input_unchanged(stamp, t: int) -> None:
    """Refuse frame ``t``, just reconstructed, when the store's input file changed since the run
    began (the frame would not be marked done).

    Cheap: the file's size, modification time and status-change time against the stamp's (its
    SHA-256 is taken once, when the store is opened). A file rewritten in place during a run
    (``cp other.tif series.tif``) would otherwise give a store whose later frames come from another
    recording than its stamp names; the status-change time, which no copy can set, also catches a
    rewrite that keeps the size and the modification time (``cp -p`` of a file of the same size).
    Inputs that are not files (arrays) are not checked.

    Parameters
    ----------
    stamp : dict or None
        The store's stamp (:data:`STAMP`); its ``input`` holds path, size, mtime_ns and ctime_ns
        (stores written before ctime_ns was stamped are checked on size and mtime_ns).
    t : int
        The frame about to be marked done.

    Raises
    ------
    SsdpcError
        The input is gone, or its size, modification or status-change time changed.
    """
    ident = stamp.get("input") if isinstance(stamp, dict) else None
    if not isinstance(ident, dict) or ident.get("size") is None or not ident.get("mtime_ns"):
        return
    path = Path(str(ident.get("path")))
    try:
        size, mtime, ctime = file_times(path)
    except OSError:
        size, mtime, ctime = -1, 0, 0
    if (size, mtime) == (ident["size"], ident["mtime_ns"]) and ctime == ident.get("ctime_ns", ctime):
        return
    if size < 0:
        now = "is gone"
    elif (size, mtime) == (ident["size"], ident["mtime_ns"]):
        now = f"was rewritten at {_when(ctime)} with the same size and time"
    else:
        now = f"is now {size} bytes, modified {_when(mtime)}"
    raise SsdpcError(
        f"{path} changed during the run (it was {ident['size']} bytes, modified {_when(ident['mtime_ns'])}; it {now}): "
        f"frame {t} was not marked done, the frames before it are of the recording the store names; restore the "
        "file and rerun to resume, or reconstruct the new recording into a new output path"
    )


def _when(mtime_ns: int) -> str:
    return datetime.datetime.fromtimestamp(mtime_ns / 1e9).isoformat(timespec="milliseconds")


def done_frames(out) -> np.ndarray:
    """Indices of the frames completely written to a series store.

    Parameters
    ----------
    out : str or Path

    Returns
    -------
    numpy.ndarray of int
    """
    import zarr

    root = zarr.open_group(str(out), mode="r")
    if DONE not in root:
        return np.zeros(0, int)
    done = root[DONE]
    # only the flags whose chunks are on disk (an unwritten flag is the fill value 0): a length that
    # claims 10^9 frames costs nothing (reading every flag would visit 10^9 absent chunks)
    written = _written_flags(Path(out) / DONE, done)
    if written.size == 0:
        return written
    return written[np.asarray(done.get_coordinate_selection(written)) == 1]


def _written_flags(folder: Path, done) -> np.ndarray:
    """Indices of the done flags whose chunk files exist (zarr v2 keys ``k``, v3 ``c/k``), sorted."""
    keys = folder / "c" if (folder / "c").is_dir() else folder
    try:
        chunks = sorted(int(p.name) for p in keys.iterdir() if p.name.isdigit())
    except OSError:  # not a local folder: every flag is read
        return np.arange(int(done.shape[0]))
    step, n = int(done.chunks[0]), int(done.shape[0])
    out = [np.arange(k * step, min((k + 1) * step, n)) for k in chunks if k * step < n]
    return np.concatenate(out) if out else np.zeros(0, int)


def read_complete(out, name: str = "ri") -> np.ndarray:
    """One image of a series store with every frame not marked done shown as NaN.

    A frame killed between its chunks may hold RI without phase; the done marker is set only
    after all its chunks, so a reader that trusts it never shows a half frame.

    Parameters
    ----------
    out : str or Path
        The store.
    name : str
        The image ('ri', 'phase', ...).

    Returns
    -------
    numpy.ndarray
        (t, ...) float32.
    """
    from napari_ssdpc.io.ome_zarr import read_ome_zarr

    arr, _, _ = read_ome_zarr(out, name)
    return np.asarray(mask_incomplete(np.array(arr[:], dtype=np.float32), out))


def mask_incomplete(data, out):
    """``data`` (t, ...) of the store ``out`` with every frame not marked done set to NaN.

    Parameters
    ----------
    data : numpy.ndarray or dask.array.Array
        (t, ...) frames; a dask array stays lazy.
    out : str or Path
        The store (its ``ssdpc_done`` array). A store without one (not a series) is returned as is.

    Returns
    -------
    numpy.ndarray or dask.array.Array
        Same type and shape, float.
    """
    import zarr

    root = zarr.open_group(str(out), mode="r")
    if DONE not in root:
        return data
    done = np.zeros(data.shape[0], bool)
    done[done_frames(out)] = True
    if done.all():
        return data
    keep = done.reshape((-1,) + (1,) * (data.ndim - 1))
    if isinstance(data, np.ndarray):
        return np.where(keep, data, np.float32(np.nan))
    import dask.array as da

    return da.where(keep, data, np.float32(np.nan))


def grow_store(out, n_frames: int) -> None:
    """Lengthen a store's t axis to ``n_frames`` (a followed recording that grew); new frames are
    not done, so readers show them as NaN until they are written.

    Parameters
    ----------
    out : str or Path
        The store (made by :func:`open_store`).
    n_frames : int
        Frames it must hold at least.
    """
    import zarr

    try:
        root = zarr.open_group(str(out), mode="r+")
        arrays = [root[DONE]] + [root[name]["0"] for name, node in root.groups() if "0" in node]
        for a in arrays:
            if a.shape[0] < n_frames:
                a.resize((int(n_frames),) + tuple(a.shape[1:]))
    except OSError as e:
        raise os_error(e, Path(out)) from None
