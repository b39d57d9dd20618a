"""Where the lenslets sit and what they see: the MLA lattice in the pupil, each lenslet's
sub-aperture centre and the parallax angle of a spatial frequency (docs/conventions.md).

The geometry every layer computes from the optics; the settings hold only the numbers.
"""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.settings.lenslets import Lenslet, circle_overlap_fraction, lattice_cell
from napari_ssdpc.settings.optics import Optics

__all__ = ["mla_to_frequency", "nominal_lenslets", "tan_theta"]


def mla_to_frequency(optics: Optics, a_um):
    """Sub-aperture centre frequency of a lenslet at MLA position ``a``.

    Parameters
    ----------
    optics : Optics
    a_um : array_like, (..., 2)
        (x, y) position on the MLA from the optical axis, µm.

    Returns
    -------
    ndarray, (..., 2)
        u_k = -a / (λ f_obj m_r), cycles/µm (docs/conventions.md: the relay inverts the BFP).
    """
    return -np.asarray(a_um, dtype=float) / (optics.wavelength_um * optics.f_obj_um * optics.m_r)


def nominal_lenslets(optics: Optics, axis_offset_um=(0.0, 0.0), min_fraction: float = 1e-3) -> list[Lenslet]:
    """Lenslets overlapping the objective pupil.

    Parameters
    ----------
    optics : Optics
    axis_offset_um : (float, float)
        Optical axis position relative to the reference lattice vertex in the MLA plane
        (x, y), µm: a lenslet centre relative to the axis is its lattice position minus it.
    min_fraction : float
        Smallest part of a lenslet inside the pupil that still counts.

    Returns
    -------
    list of Lenslet
    """
    p = optics.pitch_um
    cell = lattice_cell(optics.grid) * p
    ox, oy = (float(v) for v in axis_offset_um)
    # every index whose lenslet can reach the pupil (rows of a hex array are skewed: wider column range)
    reach = (optics.pupil_radius_mla_um + optics.lenslet_radius_um + math.hypot(ox, oy)) / cell[1, 1]
    n = int(math.ceil(reach)) + 2
    out = []
    for row in np.arange(-n, n):
        for col in np.arange(-2 * n, 2 * n):
            ax, ay = (float(v) for v in cell @ (col + 0.5, row + 0.5) - (ox, oy))
            frac = float(
                circle_overlap_fraction(math.hypot(ax, ay), optics.lenslet_radius_um, optics.pupil_radius_mla_um)
            )
            if frac >= min_fraction:
                u = mla_to_frequency(optics, (ax, ay))
                out.append(Lenslet(int(row), int(col), (ax, ay), (float(u[0]), float(u[1])), frac))
    return out


def tan_theta(optics: Optics, u) -> np.ndarray:
    """tanθ of the propagation angle in the medium, sinθ = λ|u|/n.

    Parameters
    ----------
    optics : Optics
    u : array_like, (2,) or (N, 2)
        Lateral spatial frequency, cycles/µm.

    Returns
    -------
    ndarray, (N,)
    """
    s = np.clip(optics.wavelength_um * np.linalg.norm(np.atleast_2d(u), axis=-1) / optics.medium_index, 0, 0.999999)
    return s / np.sqrt(1 - s * s)
