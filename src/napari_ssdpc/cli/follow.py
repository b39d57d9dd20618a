"""``ssdpc reconstruct --follow``: a recording reconstructed while it is being written."""

from __future__ import annotations

import sys

import numpy as np

__all__ = ["follow_recording", "followed", "report_series"]


def followed(path, idle_s):
    """The recording to follow, once its first frame has arrived.

    Parameters
    ----------
    path : str
        A TIFF, an OME-Zarr image or a folder of TIFF files being written.
    idle_s : float
        Stop after this long without a new frame, s.

    Returns
    -------
    FollowedFrames
    """
    from napari_ssdpc.io.followed import FollowedFrames

    print(f"following {path}: waiting for frames (Ctrl-C stops; a rerun resumes)", file=sys.stderr, flush=True)
    return FollowedFrames(path, idle_s=idle_s)


def follow_recording(pipeline, source, sink, out, save):
    """Reconstruct a recording as it is written; report the latency from frame on disk to result.

    Parameters
    ----------
    pipeline : Pipeline
    source : FollowedFrames
    sink : ZarrSink
    out : Path
        The store.
    save : list of str
        Quantities beside RI.
    """
    import time

    latency = []

    def written(t, done, total, result):
        latency.append(time.time() - source.arrived_at.get(t, time.time()))

    try:
        report = pipeline.run(source, sink, on_frame=written, progress=True)
    finally:
        if latency:
            print(
                f"{len(latency)} frames followed; latency from frame on disk to result {np.median(latency):.2f} s "
                f"(median), {max(latency):.2f} s (max)",
                file=sys.stderr,
            )
    print(f"no new frame for {source.idle_s:g} s: stopped", file=sys.stderr)
    report_series(report, out, save)


def report_series(report, out, save):
    """Print what a series run wrote (or that every frame was there already).

    Parameters
    ----------
    report : RunReport
    out : Path
        The store.
    save : list of str
        Quantities beside RI.
    """
    names = ", ".join(["ri", *save])
    if report.written == 0:
        print(f"{out}: all {report.frames} frames were already written ({names})")
        return
    print(
        f"wrote {out} ({report.written} of {report.frames} frames, {report.skipped} done before: {names}; "
        f"{report.frames_per_second:.2f} frames/s)"
    )
