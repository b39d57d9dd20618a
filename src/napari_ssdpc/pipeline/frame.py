"""One frame through the loop (read, reconstruct, write) and what a run did: shared by the serial
loop (:mod:`.run`) and the Dask runner (:mod:`.distributed`)."""

from __future__ import annotations

import sys
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

from napari_ssdpc.pipeline.sinks import Sink
from napari_ssdpc.pipeline.sources import FrameSource

__all__ = ["BackgroundWriter", "RunReport", "frame_bar", "process_frame"]


@dataclass
class RunReport:
    """What a run did.

    Attributes
    ----------
    frames : int
        Frames in the source at the end.
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
    dropped : list of int
        Frames a bounded live source dropped while the solver lagged (their camera indices).
    """

    frames: int
    written: int
    skipped: int
    seconds: float
    build_seconds: float
    timings: list = field(default_factory=list)
    dropped: list = field(default_factory=list)

    @property
    def frames_per_second(self) -> float:
        """Frames written per second of this run (NaN when none took time)."""
        return self.written / self.seconds if self.seconds > 0 else float("nan")


class BackgroundWriter:
    """A sink's writes beside the next frame's reconstruction: one writing thread, at most one frame
    in flight (its result held until written), errors raised at the next frame or at :meth:`close`.

    Parameters
    ----------
    sink : Sink
        Opened.
    """

    def __init__(self, sink: Sink):
        self.sink = sink
        self._pool: ThreadPoolExecutor | None = None
        self._pending: tuple[Future, dict] | None = None  # (future, timing) of the frame being written

    def write(self, t: int, result, timing: dict) -> None:
        """Start writing frame ``t`` once the frame before it is written; ``timing['write_s']`` is
        set when it is done.

        Parameters
        ----------
        t : int
        result : Result
        timing : dict
            The frame's timing (:func:`process_frame`).
        """
        self.wait()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(1, thread_name_prefix="ssdpc-write")
        self._pending = (self._pool.submit(self.sink.write, t, result), timing)

    def wait(self) -> None:
        """Until the frame in flight is written (its error raised here)."""
        if self._pending is not None:
            future, timing = self._pending
            self._pending = None
            timing["write_s"] = future.result()

    def close(self) -> None:
        """Wait for the write in flight and end the thread (after an error too: a failed write's
        frame is not marked done, and the error that stopped the run is the one raised)."""
        if self._pending is not None:
            self._pending[0].exception()  # waits; its error was or will be raised by wait()
            self._pending = None
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def process_frame(
    rec, source: FrameSource, t: int, sink: Sink, *, warm=None, progress=None, should_stop=None, writer=None
):
    """Read frame t, reconstruct it and write it (serially and on Dask workers).

    Parameters
    ----------
    rec : Reconstructor
    source : FrameSource
    t : int
        Frame index.
    sink : Sink
        Opened.
    warm : Solution, optional
        Start of an iterative method (the previous frame's solution).
    progress, should_stop : callable, optional
        Per iteration (see :meth:`Reconstructor.reconstruct`).
    writer : BackgroundWriter, optional
        Writes the result beside the next frame (``write_s`` is filled in when it is written);
        default: written here, before returning.

    Returns
    -------
    timing : dict
        ``t`` and the seconds spent reading, reconstructing and writing (plus the solver's).
    result : Result
    """
    t0 = time.perf_counter()
    frame = source[t]
    t1 = time.perf_counter()
    result = rec.reconstruct(
        frame, warm=warm, progress=progress, should_stop=should_stop, name=f"{source.name} frame {t}"
    )
    t2 = time.perf_counter()
    sink.accept(t, result)  # e.g. the input file unchanged since the run began: the frame is of it
    timing = {"t": int(t), "read_s": t1 - t0, "reconstruct_s": t2 - t1, "write_s": 0.0, **result.timings}
    if writer is None:
        timing["write_s"] = sink.write(t, result)
    else:
        writer.write(t, result, timing)
    return timing, result


def frame_bar(total, initial, show):
    """A tqdm bar of frames on stderr.

    Parameters
    ----------
    total : int or None
        Frames (None: unknown).
    initial : int
        Frames already done.
    show : bool

    Returns
    -------
    tqdm.tqdm
    """
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
