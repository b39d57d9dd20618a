"""Lenslet-array geometry shared by every layer: the lattice cell, one lenslet, the four halves.

Conventions (docs/conventions.md): MLA frame x right, y down; a lenslet's centre ``a`` is
measured from the optical axis in the MLA plane; the halves of paper Eq. 5 are named by the sign
of ``a``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from napari_ssdpc.errors import SsdpcError

__all__ = ["GRIDS", "HALVES", "PAIRS", "Lenslet", "circle_overlap_fraction", "lattice_cell"]

GRIDS = ("square", "hex")


def lattice_cell(grid: str = "square") -> np.ndarray:
    """The unit cell of a lenslet array, in pitches, in the MLA frame (x right, y down).

    Parameters
    ----------
    grid : {"square", "hex"}

    Returns
    -------
    ndarray, (2, 2)
        Columns: the step of one column and of one row. Square: (1, 0) and (0, 1). Hex: (1, 0)
        and (1/2, √3/2), so that each row is offset by half a pitch and every lenslet has six
        neighbours at one pitch.
    """
    if grid == "hex":
        return np.array([[1.0, 0.5], [0.0, math.sqrt(3.0) / 2.0]])
    if grid == "square":
        return np.eye(2)
    raise SsdpcError(f"grid must be one of {', '.join(GRIDS)}, got {grid!r}")


#: The four halves of paper Eq. 5, by the sign of the lenslet position a (x right, y down):
#: "up" = a_y < 0, "down" = a_y > 0, "left" = a_x < 0, "right" = a_x > 0.
HALVES = ("up", "down", "left", "right")
#: The two DPC pairs of paper Eq. 1: I_DPC = (first - second) / (first + second).
PAIRS = {"ud": ("up", "down"), "lr": ("left", "right")}


@dataclass(frozen=True)
class Lenslet:
    """One lenslet that overlaps the objective pupil.

    ``row``/``col`` index the lattice: the lenslet centre sits at
    ``p C (col + 0.5, row + 0.5)`` from the reference lattice vertex, with C the unit cell of
    :func:`lattice_cell` (the identity for a square array, so ``((col + 0.5) p, (row + 0.5) p)``
    and the four central lenslets are (-1,-1), (-1,0), (0,-1) and (0,0)). ``a_um`` is the centre
    measured from the optical axis in the MLA plane (x right, y down), ``u`` the
    sub-aperture centre frequency (cycles/µm), ``fraction`` the part of the lenslet
    aperture inside the objective pupil.
    """

    row: int
    col: int
    a_um: tuple[float, float]
    u: tuple[float, float]
    fraction: float

    @property
    def halves(self) -> tuple[str, ...]:
        """Halves of paper Eq. 5 this lenslet belongs to (:data:`HALVES`)."""
        ax, ay = self.a_um
        out = []
        if ay < 0:
            out.append("up")
        elif ay > 0:
            out.append("down")
        if ax < 0:
            out.append("left")
        elif ax > 0:
            out.append("right")
        return tuple(out)


def circle_overlap_fraction(d, r_small, r_big):
    """Fraction of a circle of radius ``r_small`` inside a circle of radius ``r_big``.

    Parameters
    ----------
    d : array_like
        Distance between the centres (any length unit, the same for all three).
    r_small, r_big : float or array_like
        The two radii (broadcastable with ``d``: each lenslet its own radius).

    Returns
    -------
    ndarray, float64, the broadcast shape
        Area fraction of the small circle inside the big one (exact lens-area formula).
    """
    d, r, R = np.broadcast_arrays(
        np.abs(np.asarray(d, dtype=float)), np.asarray(r_small, float), np.asarray(r_big, float)
    )
    out = np.zeros(d.shape)
    inside = d <= np.abs(R - r)
    out[inside] = np.where(r <= R, 1.0, (R / r) ** 2)[inside]
    part = (~inside) & (d < R + r)
    dp, r, R = d[part], r[part], R[part]
    a1 = r * r * np.arccos(np.clip((dp * dp + r * r - R * R) / (2 * dp * r), -1, 1))
    a2 = R * R * np.arccos(np.clip((dp * dp + R * R - r * r) / (2 * dp * R), -1, 1))
    a3 = 0.5 * np.sqrt(np.clip((-dp + r + R) * (dp + r - R) * (dp - r + R) * (dp + r + R), 0, None))
    out[part] = (a1 + a2 - a3) / (math.pi * r * r)
    return out
