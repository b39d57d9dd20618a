"""The frame loop on a Dask cluster: workers build the job's Reconstructor once and process
frames of a file into a shared OME-Zarr store (the same :func:`~.frame.process_frame`)."""

from __future__ import annotations

import time

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.pipeline.frame import RunReport, frame_bar, process_frame
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.sinks import OutputGrid, ZarrSink

__all__ = ["run_on_dask"]

_WORKER_CACHE: dict = {}


def _reconstructor(job: Job):
    """The job's Reconstructor, built once per process (a Dask worker keeps it)."""
    if job.key not in _WORKER_CACHE:
        _WORKER_CACHE.clear()  # one set of operators per worker
        _WORKER_CACHE[job.key] = job.build()
    return _WORKER_CACHE[job.key]


def _grid(job: Job) -> OutputGrid:
    return OutputGrid.of(_reconstructor(job))


def _process(job: Job, source, t: int, out: str, save) -> dict:
    """One frame on a worker: its own Reconstructor, its own handle on the store."""
    timing, _ = process_frame(_reconstructor(job), source, t, ZarrSink(out, save))
    return timing


def run_on_dask(pipeline, source, sink, *, progress: bool = True, stop_after=None) -> RunReport:
    """Spread the frames of a file over Dask workers into an OME-Zarr store.

    Parameters
    ----------
    pipeline : Pipeline
        With ``workers`` or ``scheduler``.
    source : FrameSource
        A file the workers can read (a shared file system).
    sink : ZarrSink
        A store the workers can write.
    progress : bool
        A tqdm bar of the frames.
    stop_after : int, optional
        Process at most this many pending frames.

    Returns
    -------
    RunReport
    """
    if not isinstance(sink, ZarrSink):
        raise SsdpcError("--workers/--scheduler spread the frames of a time series; write it to OME-Zarr (-o OUT.zarr)")
    if getattr(source, "path", None) is None:
        raise SsdpcError("Dask workers read the frames from a file; give the series as a TIFF path")
    from distributed import as_completed

    client, cluster = _client(pipeline.workers, pipeline.scheduler)
    job = pipeline.job
    try:
        job_f = client.scatter(job, broadcast=True)  # once per worker, not in every task (the flat is MBs)
        grid = client.submit(_grid, job_f, pure=False).result()
        done = sink.open(job, grid, source)
        try:
            pending = [t for t in range(source.available()) if t not in done]
            if stop_after is not None:
                pending = pending[: int(stop_after)]
            t0 = time.perf_counter()
            bar = frame_bar(source.available(), len(done), progress)
            futures = [client.submit(_process, job_f, source, t, str(sink.out), sink.save, pure=False) for t in pending]
            timings = []
            for fut in as_completed(futures):
                timings.append(fut.result())  # re-raises a worker's error here
                bar.update(1)
            bar.close()
        finally:
            sink.close()
        timings.sort(key=lambda d: d["t"])
        return RunReport(
            source.available(), len(pending), len(done), time.perf_counter() - t0, grid.build_seconds, timings
        )
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _client(workers, scheduler):
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SsdpcError("--workers/--scheduler need Dask distributed; pip install distributed") from None
    if scheduler is not None:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError, ValueError) as e:
            raise SsdpcError(
                f"cannot reach the Dask scheduler at {scheduler} ({type(e).__name__}); "
                "check the address, e.g. tcp://host:8786"
            ) from None
    cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=None)
    return Client(cluster), cluster
