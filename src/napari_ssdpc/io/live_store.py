"""The record of a live acquisition's store: which camera frames it holds and which were dropped.

A camera's frames are written to a series store (:mod:`.store`) as the solver takes them; when the
run ends, the root attribute ``ssdpc_live`` gives the frames kept and dropped as runs of frame numbers.
"""

from __future__ import annotations

from pathlib import Path

from napari_ssdpc.files import os_error
from napari_ssdpc.io.store import done_frames

__all__ = ["LIVE", "record_live_frames"]

LIVE = "ssdpc_live"  # root attribute of a live acquisition's store: the frames kept and dropped


def _ranges(indices) -> list[list[int]]:
    """[[first, last], ...] of the runs of consecutive indices (sorted), e.g. [0, 1, 2, 5] -> [[0, 2], [5, 5]]."""
    runs: list[list[int]] = []
    for t in sorted(int(t) for t in indices):
        if runs and t == runs[-1][1] + 1:
            runs[-1][1] = t
        else:
            runs.append([t, t])
    return runs


def record_live_frames(out, summary: dict) -> dict:
    """Write which frames of a live acquisition the store holds and which were dropped (attribute ``ssdpc_live``).

    Parameters
    ----------
    out : str or Path
        The store.
    summary : dict
        The source's ``summary()``: ``frames`` (frames the camera gave), ``dropped`` (indices the solver
        could not keep up with) and ``maxsize`` (the queue's bound; None: every frame kept).

    Returns
    -------
    dict
        What was written: ``frames``, ``kept`` and ``dropped`` (runs ``[[first, last], ...]`` of frame
        indices), ``maxsize``. Frames neither kept nor dropped were cut off by a stop or an error.
    """
    import zarr

    record = {
        "frames": int(summary["frames"]),
        "kept": _ranges(done_frames(out)),
        "dropped": _ranges(summary["dropped"]),
        "maxsize": summary["maxsize"],
    }
    try:
        zarr.open_group(str(out), mode="r+").attrs[LIVE] = record
    except OSError as e:
        raise os_error(e, Path(out)) from None
    return record
