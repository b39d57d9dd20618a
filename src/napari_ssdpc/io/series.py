"""Time series at scale: stream raw frames through a Reconstructor into a (t, z, y, x) OME-Zarr.

- Streaming: frames are read one at a time (a memory map of an uncompressed TIFF, else one
  page at a time), so memory is bounded by a few frames whatever the series length.
- Output: one OME-Zarr image group per quantity (``ri`` and the requested extras), chunked
  one frame per chunk (``io.create_ome_zarr``).
- Resumable and crash-safe: zarr writes every chunk to a temporary file and renames it, and a
  frame is marked done (one byte in the ``ssdpc_done`` array) only after all its chunks are
  written. A rerun with the same input and settings skips the frames marked done; frames left
  unmarked by an interrupted run read as NaN, never as garbage, until they are redone.
- Scale-out: ``workers=N`` runs the same per-frame function on a local Dask cluster,
  ``scheduler=ADDRESS`` on an existing one. Workers build their own Reconstructor from a small
  :class:`Recipe` (once per worker process) and read and write the files themselves, so the
  input and output paths must be visible to them (a shared file system).
"""

from __future__ import annotations

import functools
import hashlib
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import os_error
from napari_ssdpc.io.frame_source import FrameSource
from napari_ssdpc.io.store import DONE, StoreLock, done_frames, open_store
from napari_ssdpc.reconstruction import outputs

__all__ = ["DONE", "FrameSource", "Recipe", "SeriesReport", "done_frames", "process_frame", "reconstruct_series"]


# ----------------------------------------------------------------- recipe
@dataclass
class Recipe:
    """Everything that builds a Reconstructor; small enough to send to Dask workers."""

    optics: object
    calibration: object
    settings: dict = field(default_factory=dict)  # Reconstructor keywords (z, dz, iterations, ...)
    flat: np.ndarray | None = None

    def build(self, progress=None):
        """The Reconstructor of this recipe (operators built now).

        Parameters
        ----------
        progress : callable, optional
            ``progress(done, total, label)`` while the operators are built.

        Returns
        -------
        Reconstructor
        """
        from napari_ssdpc.reconstruction.pipeline import Reconstructor

        return Reconstructor(self.optics, self.calibration, flat=self.flat, progress=progress, **self.settings)

    @functools.cached_property
    def key(self) -> str:
        """Identifies the operators (a Dask worker's cache)."""
        return self._hash(self.settings)

    @functools.cached_property
    def result_key(self) -> str:
        """Identifies the results: the key without the device (CPU and GPU agree to float
        rounding), so that a run may be resumed on the other device."""
        return self._hash({k: v for k, v in self.settings.items() if k != "device"})

    def _hash(self, settings) -> str:
        h = hashlib.sha256()
        h.update(json.dumps(self.optics.to_dict(), sort_keys=True, default=str).encode())
        h.update(json.dumps(self.calibration.to_dict(), sort_keys=True, default=str).encode())
        h.update(json.dumps(settings, sort_keys=True, default=str).encode())
        if self.flat is not None:
            h.update(np.ascontiguousarray(self.flat).tobytes())
        return h.hexdigest()[:16]


_WORKER_CACHE: dict = {}


def _reconstructor(recipe: Recipe):
    """The Reconstructor of this recipe, built once per process (a Dask worker keeps it)."""
    key = recipe.key
    if key not in _WORKER_CACHE:
        _WORKER_CACHE.clear()  # one set of operators per worker
        _WORKER_CACHE[key] = recipe.build()
    return _WORKER_CACHE[key]


# ---------------------------------------------------------------- outputs
def _describe(recipe: Recipe, save):
    rec = _reconstructor(recipe)
    return _grid(rec, save)


def _grid(rec, save):
    """(layout, voxel µm, origin µm, settings, build s) of a Reconstructor's output."""
    dz, dy = rec.dz, rec.pixel_um
    origin = (float(rec.z_um[0]), float(rec.y_um[0]), float(rec.x_um[0]))  # the optical axis at y = x = 0
    return outputs.layout(len(rec.z_um), rec.mask.shape, save), (dz, dy, dy), origin, rec.settings(), rec.build_seconds


def _write_frame(out: Path, t: int, images: dict) -> float:
    import zarr

    t0 = time.perf_counter()
    try:
        root = zarr.open_group(str(out), mode="r+")
        for name, (data, _, _) in images.items():
            root[name]["0"][t] = data
        root[DONE][t] = 1  # only after every chunk of the frame is on disk
    except OSError as e:
        raise os_error(e, out) from None
    return time.perf_counter() - t0


#: |Δn| beyond this is no sample in any medium: a wrong input or setting.
MAX_DELTA_N = 0.5


def _check_values(result, t: int) -> None:
    """Refuse to write a frame whose RI is non-finite or unphysical (the run stops, resumable)."""
    dn = np.asarray(result.ri, np.float64) - float(np.median(result.ri))
    if not np.all(np.isfinite(dn)):
        raise SsdpcError(
            f"frame {t}: the reconstruction holds NaN/inf values and was not written; check the frame, --dz and --alpha"
        )
    peak = float(np.max(np.abs(dn))) if dn.size else 0.0
    if peak > MAX_DELTA_N:
        raise SsdpcError(
            f"frame {t}: |Δn| reaches {peak:.3g}, beyond any sample (±{MAX_DELTA_N}); not written. Likely the "
            "condenser NA of the optics differs from the one the frames were recorded with, or --alpha is too small"
        )


def process_frame(rec_or_recipe, source: FrameSource, t: int, out, save) -> dict:
    """Read frame t, reconstruct it, write its chunks and mark it done (serially and on Dask workers).

    Parameters
    ----------
    rec_or_recipe : Reconstructor or Recipe
        A built Reconstructor, or a Recipe (a worker builds it once and keeps it).
    source : FrameSource
        The raw frames (t, y, x).
    t : int
        Frame index.
    out : str or Path
        The OME-Zarr store (made by :func:`~napari_ssdpc.io.store.open_store`).
    save : list of str
        Quantities written beside RI (registry names).

    Returns
    -------
    dict
        ``t`` and the seconds spent reading, reconstructing and writing (plus the solver's timings).
    """
    rec = _reconstructor(rec_or_recipe) if isinstance(rec_or_recipe, Recipe) else rec_or_recipe
    t0 = time.perf_counter()
    frame = source[t]
    t1 = time.perf_counter()
    result = rec.reconstruct(frame)
    _check_values(result, t)
    t2 = time.perf_counter()
    write = _write_frame(Path(out), t, outputs.images(result, save))
    return {"t": int(t), "read_s": t1 - t0, "reconstruct_s": t2 - t1, "write_s": write, **result.timings}


# ------------------------------------------------------------------- driver
@dataclass
class SeriesReport:
    """What a series run did.

    Attributes
    ----------
    frames : int
        Frames in the series.
    written : int
        Frames reconstructed and written by this run.
    skipped : int
        Frames already done by an earlier run (resumed).
    seconds : float
        Wall time of this run's frames, s.
    build_seconds : float
        Time to build the operators, s.
    timings : list of dict
        Per frame, as :func:`process_frame` returns them.
    """

    frames: int
    written: int
    skipped: int
    seconds: float
    build_seconds: float
    timings: list

    @property
    def frames_per_second(self) -> float:
        """Frames written per second of this run (NaN when none took time)."""
        return self.written / self.seconds if self.seconds > 0 else float("nan")


def reconstruct_series(
    source,
    out,
    recipe: Recipe,
    *,
    save=(),
    meta=None,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    rec=None,
    stop_after: int | None = None,
    on_frame=None,
) -> SeriesReport:
    """Stream a series through the recipe's Reconstructor into an OME-Zarr store (see the module notes).

    Parameters
    ----------
    source : FrameSource, str, Path or array
        The raw frames (t, y, x): a TIFF path, a NumPy or dask array.
    out : str or Path
        The ``.zarr`` store; an existing one of the same input and settings is resumed.
    recipe : Recipe
        What builds the Reconstructor.
    save : iterable of str
        Quantities written beside RI (registry names).
    meta : dict, optional
        Metadata stored with every image.
    workers : int, optional
        Local Dask worker processes.
    scheduler : str, optional
        Address of a running Dask scheduler.
    progress : bool
        Show a tqdm bar.
    rec : Reconstructor, optional
        Already built from this recipe (serial runs only).
    stop_after : int, optional
        Process at most this many pending frames (a partial run, for tests and previews).
    on_frame : callable, optional
        ``on_frame(t, done, total)`` after each frame is written (serial runs; raising there stops
        the run between frames, and the store stays resumable).

    Returns
    -------
    SeriesReport
    """
    source = source if isinstance(source, FrameSource) else FrameSource(source)
    out = Path(out)
    if not out.parent.is_dir():
        raise SsdpcError(f"output folder does not exist: {out.parent} (create it first)")
    if out.exists() and not out.is_dir():
        raise SsdpcError(f"{out} exists and is a file, not an OME-Zarr folder; choose a new output path")
    save = [s for s in save]
    save = outputs.parse_save(save)
    if workers is not None and workers < 1:
        raise SsdpcError(f"--workers must be >= 1, got {workers}")
    distributed = workers is not None or scheduler is not None
    if distributed and source.path is None:
        raise SsdpcError("Dask workers read the frames from a file; give the series as a TIFF path")
    if tuple(source.shape[1:]) != tuple(recipe.calibration.frame_shape):
        raise SsdpcError(
            f"{source.name}: frames of shape {source.shape[1:]} differ from the calibration's "
            f"{tuple(recipe.calibration.frame_shape)}; use the calibration of this camera ROI"
        )
    cluster = client = None
    lock = StoreLock(out)
    lock.__enter__()  # one writer per store
    try:
        if distributed:
            client, cluster = _client(workers, scheduler)
            layout, voxel, origin, settings, build = client.submit(_describe, recipe, save, pure=False).result()
        else:
            rec = recipe.build() if rec is None else rec
            layout, voxel, origin, settings, build = _grid(rec, save)
        stamp = {
            "input": source.identity(),
            "frames": len(source),
            "frame_shape": list(source.shape[1:]),
            "recipe": recipe.result_key,
            "outputs": sorted(layout),
        }
        attrs = {**(meta or {}), "settings": settings}
        done = open_store(out, len(source), layout, voxel, stamp, attrs, origin)
        finished = set(np.flatnonzero(done[:] == 1).tolist())
        pending = [t for t in range(len(source)) if t not in finished]
        if stop_after is not None:
            pending = pending[: int(stop_after)]
        t0 = time.perf_counter()
        bar = _bar(len(source), len(finished), progress)
        timings = []
        if distributed:
            timings = _run_distributed(client, recipe, source, pending, out, save, bar)
        else:
            for t in pending:
                timings.append(process_frame(rec, source, t, out, save))
                bar.update(1)
                if on_frame is not None:
                    on_frame(t, len(finished) + len(timings), len(source))
        bar.close()
        return SeriesReport(
            len(source),
            len(pending),
            len(finished),
            time.perf_counter() - t0,
            build,
            sorted(timings, key=lambda d: d["t"]),
        )
    finally:
        lock.__exit__(None, None, None)
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


def _bar(total, initial, show):
    from tqdm.auto import tqdm

    return tqdm(
        total=total,
        initial=initial,
        desc="frames",
        unit="frame",
        file=sys.stderr,
        dynamic_ncols=True,
        disable=not show,
        smoothing=0.1,
    )


def _client(workers, scheduler):
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SsdpcError("--workers/--scheduler need Dask distributed; pip install distributed") from None
    if scheduler is not None:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as e:
            raise SsdpcError(
                f"cannot reach the Dask scheduler at {scheduler} ({type(e).__name__}); "
                "check the address, e.g. tcp://host:8786"
            ) from None
    cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=None)
    return Client(cluster), cluster


def _run_distributed(client, recipe, source, pending, out, save, bar):
    from distributed import as_completed

    recipe_f = client.scatter(recipe, broadcast=True)
    futures = [client.submit(process_frame, recipe_f, source, t, str(out), save, pure=False) for t in pending]
    timings = []
    for fut in as_completed(futures):
        timings.append(fut.result())  # re-raises a worker's error here
        bar.update(1)
    return timings
