"""Samples that move or change from frame to frame, for the time-series tests and benchmarks: one
phantom of :mod:`.phantoms` per frame (a swimmer, a cell gliding beside a resting bead, a cell that
changes shape)."""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.simulation.phantom_base import Composite
from napari_ssdpc.simulation.phantoms import Cell, Sphere

__all__ = ["changing_cell", "gliding_cell_and_bead", "moving_sample"]


def moving_sample(
    n_frames, start_um=(-35.0, -10.0, -10.0), end_um=(35.0, 10.0, 10.0), turn_deg=60.0, **kw
) -> list[Cell]:
    """A swimmer: an ellipsoid (n 1.36, 9 x 5 x 4 µm semi-axes) with a 2 µm inclusion
    (n 1.42) moving in a straight line from ``start_um`` to ``end_um`` while it turns by
    ``turn_deg``, in water; one phantom per frame.

    Parameters
    ----------
    n_frames : int
        Number of frames (phantoms).
    start_um, end_um : (float, float, float)
        (x, y, z) of the path's ends, µm.
    turn_deg : float
        Rotation over the path, degrees.
    **kw
        More Cell fields.

    Returns
    -------
    list of Cell
    """
    if int(n_frames) < 1:
        raise SsdpcError(f"moving_sample needs n_frames >= 1, got {n_frames}")
    base = dict(
        semi_axes_um=(9.0, 5.0, 4.0),
        n=1.36,
        nucleus_offset_um=(4.0, 0.0, 0.0),
        nucleus_semi_axes_um=(2.0, 2.0, 2.0),
        n_nucleus=1.42,
        medium_index=1.33,
    )
    base.update(kw)
    s, e = np.asarray(start_um, float), np.asarray(end_um, float)
    out = []
    for i in range(int(n_frames)):
        f = i / max(int(n_frames) - 1, 1)
        c = s + f * (e - s)
        out.append(Cell(center_um=tuple(float(v) for v in c), angle_deg=float(f * turn_deg), **base))
    return out


#: The cell of the temporal-prior series: 8 x 5 x 3.5 µm semi-axes, n 1.34 in water, a 2.5 µm
#: nucleus of n 1.355 (about 1.5 rad through its centre at 520 nm: within the first-order model).
_SMALL_CELL = dict(
    semi_axes_um=(8.0, 5.0, 3.5),
    n=1.34,
    nucleus_offset_um=(2.0, 0.0, 0.0),
    nucleus_semi_axes_um=(2.5, 2.5, 2.0),
    n_nucleus=1.355,
    medium_index=1.33,
)


def gliding_cell_and_bead(
    n_frames, start_um=(-22.0, -8.0, -6.0), end_um=(-4.0, 4.0, 6.0), bead_um=(22.0, 10.0, -4.0)
) -> list[Composite]:
    """A cell gliding in x, y and z beside a resting bead, in water; one phantom per frame.

    The cell (8 x 5 x 3.5 µm semi-axes, n 1.34, nucleus n 1.355) moves in a straight line from
    ``start_um`` to ``end_um``; the bead (6 µm, n 1.34: Δn 0.01, 0.72 rad through its centre at
    520 nm) rests at ``bead_um``.

    Parameters
    ----------
    n_frames : int
        Number of frames (phantoms).
    start_um, end_um, bead_um : (float, float, float)
        (x, y, z) of the cell's path's ends and of the bead, µm.

    Returns
    -------
    list of Composite
        Items: [cell, nucleus, bead], Δn relative to water.
    """
    if int(n_frames) < 1:
        raise SsdpcError(f"gliding_cell_and_bead needs n_frames >= 1, got {n_frames}")
    bead = Sphere(tuple(map(float, bead_um)), 6.0, 1.34).parts(1.33)
    s, e = np.asarray(start_um, float), np.asarray(end_um, float)
    out = []
    for i in range(int(n_frames)):
        c = s + i / max(int(n_frames) - 1, 1) * (e - s)
        moving = Cell(center_um=tuple(float(v) for v in c), **_SMALL_CELL).parts(1.33)
        out.append(Composite(tuple(moving + bead), medium_index=1.33))
    return out


def changing_cell(n_frames, center_um=(0.0, 0.0, 0.0), amplitude=0.25, period_frames=8.0) -> list[Cell]:
    """A resting cell that changes shape: its semi-axes oscillate, one phantom per frame.

    The cell of :func:`gliding_cell_and_bead` at ``center_um``; at frame t its x semi-axis is
    scaled by 1 + a sin(2πt/T) and its y semi-axis by 1 − a sin(2πt/T) (a = ``amplitude``,
    T = ``period_frames``), its z semi-axis by 1 + a/2 cos(2πt/T); the nucleus keeps its size.

    Parameters
    ----------
    n_frames : int
        Number of frames (phantoms).
    center_um : (float, float, float)
        (x, y, z) of the centre, µm.
    amplitude : float
        Relative change of the semi-axes, in [0, 0.5].
    period_frames : float
        Period of the oscillation, frames.

    Returns
    -------
    list of Cell
    """
    if int(n_frames) < 1 or not 0 <= amplitude <= 0.5:
        raise SsdpcError(f"changing_cell needs n_frames >= 1 and amplitude in [0, 0.5], got {n_frames}, {amplitude}")
    ax, ay, az = _SMALL_CELL["semi_axes_um"]
    base = {k: v for k, v in _SMALL_CELL.items() if k != "semi_axes_um"}
    out = []
    for i in range(int(n_frames)):
        s, c = math.sin(2 * math.pi * i / period_frames), math.cos(2 * math.pi * i / period_frames)
        axes = (ax * (1 + amplitude * s), ay * (1 - amplitude * s), az * (1 + amplitude / 2 * c))
        out.append(Cell(center_um=tuple(map(float, center_um)), semi_axes_um=axes, **base))
    return out
