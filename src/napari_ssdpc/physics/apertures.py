"""Apertures and the Köhler source sampled on a periodic frequency lattice (cycles/µm).

- The objective pupil P_obj(u) = circ(|u| ≤ NA/λ) and the sub-aperture of lenslet k,
  A_k(u) = P_obj(u)·circ(|u − u_k| ≤ ρ) (paper Eq. 2), sampled as the exact area fraction of each
  lattice cell inside them (the apertures of :class:`~napari_ssdpc.physics.pupil.Pupil`, which
  ``physics.pupil.subaperture_pupil`` samples with a linear edge ramp instead).
- Köhler illumination sampled as plane waves on the lattice (Abbe's method, paper Eq. 2): source
  points over the condenser disk |w| ≤ NA_c/λ, each weighted by the area of its cell in the disk,
  and per lenslet by the part of the cell on the lit side of that lenslet's edge.

The wave propagation these feed is in :mod:`napari_ssdpc.physics.waves`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from napari_ssdpc.physics.pupil import Pupil

__all__ = [
    "cell_fraction",
    "disk_fraction",
    "kohler_source",
    "lenslet_source_weights",
    "subaperture_windows",
]


# ------------------------------------------------------------------ apertures on cells
def cell_fraction(inside, x, y, cell: float, supersample: int) -> np.ndarray:
    """Fraction of each square cell (side ``cell``, centred at x, y) where ``inside`` holds.

    The cell is sampled on ``supersample`` x ``supersample`` sub-cell centres.

    Parameters
    ----------
    inside : callable
        ``inside(sx, sy)`` -> bool array, for broadcast sample coordinates.
    x, y : ndarray
        Cell centres (broadcastable), any unit.
    cell : float
        Cell side, same unit.
    supersample : int
        Sub-samples per cell side.

    Returns
    -------
    ndarray, float64
        Fraction in [0, 1], the broadcast shape of ``x`` and ``y``.
    """
    t = ((np.arange(supersample) + 0.5) / supersample - 0.5) * cell
    sx = np.asarray(x)[..., None, None] + t[None, :]
    sy = np.asarray(y)[..., None, None] + t[:, None]
    return np.mean(inside(sx, sy), axis=(-2, -1))


def disk_fraction(x, y, radius, pixel, supersample=8):
    """Fraction of each pixel (side ``pixel``, centred at x, y) inside the disk r <= radius.

    Parameters
    ----------
    x, y : ndarray
        Pixel centres (broadcast), any length unit.
    radius : float
        Disk radius, same unit.
    pixel : float
        Pixel side, same unit.
    supersample : int
        Sub-samples per pixel side for the pixels on the edge.

    Returns
    -------
    ndarray, float64
        Fraction in [0, 1], the broadcast shape of ``x`` and ``y``.
    """
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    r = np.hypot(x, y)
    out = (r <= radius).astype(np.float64)
    edge = np.abs(r - radius) < pixel  # a pixel farther than its side from the rim is wholly in or out
    if edge.any():
        out[edge] = cell_fraction(
            lambda sx, sy: sx * sx + sy * sy <= radius * radius, x[edge], y[edge], pixel, supersample
        )
    return out


def lenslet_source_weights(
    w, spacing: float, radius: float, lenslets, pupil: Pupil, supersample=8, max_samples=250_000, centre=(0.0, 0.0)
):
    """Per-lenslet weights of lattice source points, so each lenslet's bright-field edge is exact.

    A view's intensity jumps where a source point's direct light crosses the edge of the lenslet's
    sub-aperture. Weighting every point by its own cell (:func:`kohler_source`) counts the cells that
    straddle that edge wholly on the side of their centre: an error of the order of the spacing in
    the bright-field area, which matters when a sub-aperture holds only a few points. Here the
    condenser disk is sampled ``supersample`` times finer than the points, and every sample is
    given to the nearest point whose direct light falls on the same side of the lenslet's edge
    (inside or outside A_k) as the sample's: per lenslet, the points share the disk's area, and
    the bright part of it is carried by bright points only.

    Parameters
    ----------
    w : ndarray, (S, 2)
        Source points (ux, uy), cycles/µm, on a square lattice of step ``spacing``.
    spacing : float
        Lattice step, cycles/µm.
    radius : float
        Condenser disk radius NA_c/λ, cycles/µm.
    lenslets : list of Lenslet, or array_like (K, 2)
        The lenslets (their own sub-apertures), or bare centres u_k (x, y), cycles/µm.
    pupil : Pupil
        The objective pupil and the sub-apertures.
    supersample : int
        Samples of the disk per lattice step.
    max_samples : int
        At most this many samples of the disk (fewer per step for a fine lattice).
    centre : (float, float)
        The disk's centre (x, y), cycles/µm (a condenser off axis).

    Returns
    -------
    ndarray, float64, (S, K)
        Area of the disk each point carries for each lenslet, (cycles/µm)²; every column sums to
        the disk's area (to the sampling).
    """
    w = np.asarray(w, float)
    h = max(spacing / supersample, radius * math.sqrt(math.pi / max_samples))
    m = int(math.ceil(radius / h))
    t = (np.arange(-m, m) + 0.5) * h
    sx, sy = np.meshgrid(t, t)
    keep = sx * sx + sy * sy <= radius * radius
    v = np.stack([sx[keep], sy[keep]], axis=1) + np.asarray(centre, float)
    out = np.zeros((len(w), len(lenslets)))
    for k, lenslet in enumerate(lenslets):
        u_k, rho_k, _ = pupil.lenslet(lenslet)  # its own centre and radius
        bright_v = pupil.subaperture(v[:, 0], v[:, 1], u_k, rho=rho_k)
        bright_w = pupil.subaperture(w[:, 0], w[:, 1], u_k, rho=rho_k)
        for side in (True, False):
            pts = np.flatnonzero(bright_w == side)
            if not len(pts):  # no point on this side: the nearest of any side carries it
                pts = np.arange(len(w))
            samples = v[bright_v == side]
            if len(samples):
                _, nearest = cKDTree(w[pts]).query(samples)
                out[:, k] += np.bincount(pts[nearest], minlength=len(w)) * h * h
    return out


def subaperture_windows(lenslets, pupil: Pupil, du: float, nc: int, supersample: int = 8):
    """Each lenslet's sub-aperture A_k on an ``nc`` x ``nc`` crop of the lattice around u_k.

    The crop is centred on the lattice point nearest u_k; each cell passes the amplitude
    sqrt(area fraction of the cell in A_k), so |A_k|² integrates to the sub-aperture's area.

    Parameters
    ----------
    lenslets : list of Lenslet, or array_like (K, 2)
        The lenslets (their own sub-apertures), or bare centres u_k (x, y), cycles/µm.
    pupil : Pupil
        The objective pupil and the sub-apertures, with their phase.
    du : float
        Lattice step, cycles/µm.
    nc : int
        Crop width, lattice units.
    supersample : int
        Sub-samples per lattice cell side.

    Returns
    -------
    centres : ndarray, int, (K, 2)
        Lattice index (ix, iy) of each crop centre, the nearest to u_k (units of du).
    apertures : ndarray, float32 or complex64, (K, nc, nc)
        A_k on the crop (rows y, columns x), amplitude in [0, 1]; complex with the lenslet's own
        defocus where it has one (the objective's phase is not in it: the simulator applies it at
        the objective's pupil, before the field stop).
    """
    off = np.arange(nc) - nc // 2
    centres, apert = [], []
    for lenslet in lenslets:
        u_k, rho_k, defocus = pupil.lenslet(lenslet)  # its own centre, radius and defocus
        c = np.rint(np.asarray(u_k) / du).astype(int)
        ux, uy = (c[0] + off) * du, (c[1] + off) * du

        def inside(sx, sy, u_k=u_k, rho_k=rho_k):
            return pupil.subaperture(sx, sy, u_k, rho=rho_k)

        centres.append(c)
        a = np.sqrt(cell_fraction(inside, ux[None, :], uy[:, None], du, supersample))
        if defocus:  # the lenslet's own phase at the cell centres (the objective's comes before the iris)
            a = a * np.exp(1j * pupil.phase(ux[None, :], uy[:, None], u_k, rho_k, defocus, objective=False))
        apert.append(a)
    return np.array(centres), np.array(apert, dtype=np.complex64 if np.iscomplexobj(apert) else np.float32)


# ---------------------------------------------------------------------------- source
def kohler_source(radius: float, du: float, step: int = 2, supersample: int = 64, centre=(0.0, 0.0)):
    """Köhler illumination as plane waves on the lattice: points over the condenser disk with weights.

    Points every ``step`` lattice units; each is weighted by the area of its step x step cell inside
    the disk |w| ≤ ``radius`` (so the weights sum to the disk's area; Abbe's method, paper Eq. 2:
    the intensities of the points add).

    Parameters
    ----------
    radius : float
        Condenser disk radius NA_c/λ, cycles/µm.
    du : float
        Lattice step, cycles/µm.
    step : int
        Spacing of the points, lattice units.
    supersample : int
        Sub-cells per cell side for the cells on the disk's edge.
    centre : (float, float)
        The disk's centre (x, y), cycles/µm (a condenser off axis).

    Returns
    -------
    idx : ndarray, int, (K, 2)
        Lattice indices (ix, iy), units of du.
    w : ndarray, (K, 2)
        Plane-wave frequencies (ux, uy), cycles/µm.
    weights : ndarray, (K,)
        Area of each point's cell inside the disk, (cycles/µm)².
    """
    h = int(step)
    cx, cy = (float(c) for c in centre)
    m = int(math.ceil((radius + math.hypot(cx, cy)) / (h * du))) + 1
    i = np.arange(-m, m + 1)
    gx, gy = np.meshgrid(i, i)
    ix, iy = gx.ravel(), gy.ravel()
    wgt = disk_fraction(ix * h * du - cx, iy * h * du - cy, radius, h * du, supersample) * (h * du) ** 2
    keep = wgt > 0
    idx = np.stack([ix[keep] * h, iy[keep] * h], axis=1)
    return idx, idx * du, wgt[keep]
