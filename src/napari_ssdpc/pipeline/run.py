"""The frame loop: one object takes a frame source and writes results to a sink.

For every frame not yet done: read it, reconstruct it (the Reconstructor checks the frame once,
extracts its views once and checks the result before anything is written), write it, in a thread
beside the next frame's reconstruction. The CLI, the
napari widgets, the benchmark and the Dask runner all go through :class:`Pipeline`. A source of
unknown length (:class:`~.sources.LiveFrames`) is followed until it is finished.
"""

from __future__ import annotations

import os
import re
import time

from napari_ssdpc.errors import Cancelled, SsdpcError
from napari_ssdpc.pipeline.frame import BackgroundWriter, RunReport, frame_bar, process_frame
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.sinks import OutputGrid, Sink
from napari_ssdpc.pipeline.sources import as_source, grows

__all__ = ["Pipeline"]

#: How long the loop waits for a live source's next frame before it checks for a stop, s.
POLL_S = 0.2


#: A Dask scheduler's address: ``protocol://host:port`` or ``host:port``.
_SCHEDULER = re.compile(r"[a-z][a-z0-9+]*://\S+|[^\s/:]+:\d{1,5}")


class Pipeline:
    """One job, built once; :meth:`run` streams any frame source into any sink.

    Parameters
    ----------
    job : Job
        Configuration, calibration and flat.
    reconstructor : Reconstructor, optional
        Already built from this job (napari keeps one between runs).
    progress : callable, optional
        ``progress(done, total, label)`` while the operators are built.
    workers : int, optional
        Local Dask worker processes (frames of a file into a store, in parallel).
    scheduler : str, optional
        Address of a running Dask scheduler.
    """

    def __init__(self, job: Job, *, reconstructor=None, progress=None, workers=None, scheduler=None):
        if not isinstance(job, Job):
            raise SsdpcError(f"Pipeline takes a Job (configuration, calibration, flat), got {type(job).__name__}")
        if workers is not None and workers < 1:
            raise SsdpcError(f"--workers must be >= 1, got {workers}")
        cores = os.cpu_count() or 1
        if workers is not None and scheduler is None and workers > cores:
            raise SsdpcError(
                f"--workers {workers}: this machine has {cores} cores, and each worker builds its own operators; "
                f"give at most {cores}, or --scheduler for a cluster"
            )
        if scheduler is not None and not _SCHEDULER.fullmatch(str(scheduler)):
            raise SsdpcError(
                f"Dask scheduler address {scheduler!r}: give it as tcp://host:port (e.g. tcp://10.0.0.5:8786)"
            )
        self.job = job
        self.distributed = workers is not None or scheduler is not None
        self.workers, self.scheduler = workers, scheduler
        self.reconstructor = reconstructor
        if reconstructor is None and not self.distributed:
            self.reconstructor = job.build(progress)

    def run(
        self,
        source,
        sink: Sink,
        *,
        progress: bool | None = None,
        on_frame=None,
        iteration_progress=None,
        should_stop=None,
        stop_after: int | None = None,
        warm_start: bool | None = None,
    ) -> RunReport:
        """Reconstruct every frame of ``source`` that ``sink`` does not hold yet.

        Parameters
        ----------
        source : FrameSource, str, Path or array
            Raw frames (t, y, x) or one frame (y, x).
        sink : Sink
        progress : bool, optional
            A tqdm bar of the frames on stderr (default: for series of more than one frame).
        on_frame : callable, optional
            ``on_frame(t, done, total, result)`` after each frame is reconstructed (``total`` None
            for a live source), while it is written beside the next frame's reconstruction (the
            store holds it when the next frame is reconstructed, or when the run returns);
            raising there stops the run between frames.
        iteration_progress : callable, optional
            ``progress(done, total, label)`` within each frame.
        should_stop : callable, optional
            True stops the run (:class:`~napari_ssdpc.errors.Cancelled`).
        stop_after : int, optional
            Process at most this many pending frames (a partial run, for tests and previews).
        warm_start : bool, optional
            Start every frame's iterative solve where the previous frame's ended (default: the
            configuration's ``reconstruction.warm_start``). A frame after one done by an earlier
            run starts cold; Dask runs solve every frame cold.

        Returns
        -------
        RunReport
        """
        if not isinstance(sink, Sink):
            raise SsdpcError(f"the results need a Sink (MemorySink, OmeTiffSink, ZarrSink), got {type(sink).__name__}")
        if stop_after is not None and not (isinstance(stop_after, int) and stop_after >= 0):
            raise SsdpcError(f"stop_after = {stop_after!r}: give a number of frames >= 0, or None")
        source = as_source(source)
        cal_shape = tuple(self.job.calibration.frame_shape)
        if tuple(source.frame_shape) != cal_shape:
            raise SsdpcError(
                f"{source.name}: the frame shape {tuple(source.frame_shape)} differs from the calibration's "
                f"{cal_shape}; use the calibration of this camera ROI"
            )
        if self.distributed:
            from napari_ssdpc.pipeline.distributed import run_on_dask

            return run_on_dask(self, source, sink, progress=progress is not False, stop_after=stop_after)
        rec = self.reconstructor
        if warm_start is None:
            warm_start = bool(self.job.config.reconstruction.warm_start)
        done = sink.open(self.job, OutputGrid.of(rec), source)
        try:
            return self._loop(
                rec, source, sink, done, progress, on_frame, iteration_progress, should_stop, stop_after, warm_start
            )
        finally:
            sink.close()

    def _loop(
        self, rec, source, sink, done, progress, on_frame, iteration_progress, should_stop, stop_after, warm_start
    ):
        total = None if grows(source) or not source.finished() else source.available()
        show = progress if progress is not None else (total is None or total > 1)
        bar = frame_bar(total, len(done), show)
        t0, timings, warm, t = time.perf_counter(), [], None, 0
        # a bounded live source may drop a frame the solver has not come to: claim it first
        claim = getattr(source, "claim", lambda t: True)
        limit = float("inf") if stop_after is None else int(stop_after)
        writer = BackgroundWriter(sink)  # frame t is written while frame t + 1 is reconstructed
        try:
            while len(timings) < limit:
                if should_stop is not None and should_stop():
                    raise Cancelled("reconstruction cancelled")
                if t >= source.available():
                    if source.finished():
                        break
                    source.wait(POLL_S)
                    continue
                if t in done:
                    warm = None  # the next frame's neighbour was solved by another run
                elif claim(t):
                    timing, result = process_frame(
                        rec,
                        source,
                        t,
                        sink,
                        warm=warm,
                        progress=iteration_progress,
                        should_stop=should_stop,
                        writer=writer,
                    )
                    timings.append(timing)
                    warm = result.solution if warm_start else None
                    bar.update(1)
                    if on_frame is not None:
                        on_frame(t, len(done) + len(timings), total, result)
                # else dropped by a bounded live source: the next frame starts from the last one solved
                t += 1
            writer.wait()
        finally:
            writer.close()
            bar.close()
        frames = source.available()
        dropped = list(source.dropped()) if hasattr(source, "dropped") else []
        return RunReport(frames, len(timings), len(done), time.perf_counter() - t0, rec.build_seconds, timings, dropped)
