"""Scalar wave optics on a periodic frequency lattice: the pieces a wave model of the instrument shares.

- Angular-spectrum propagation in a homogeneous medium (paper Eq. 6, the free-space propagation
  between the planes of the multislice and from the sample to the focal plane): a plane wave
  exp(i2π(u·x + η z)) with η(u) = sqrt((n/λ)² − |u|²) (:func:`napari_ssdpc.physics.pupil.eta`)
  gains exp(i2π d η(u)) over a distance d toward the objective, so a field's spectrum is
  multiplied by the transfer function H_d(u) = exp(i2π d η(u)). Evanescent components
  (|u| > n/λ, η imaginary) decay over |d| in either direction, or are cut.
- The objective pupil P_obj(u) = circ(|u| ≤ NA/λ) and the sub-aperture of lenslet k,
  A_k(u) = P_obj(u)·circ(|u − u_k| ≤ ρ) (paper Eq. 2), sampled as the exact area fraction of each
  lattice cell inside them (``physics.pupil.subaperture_pupil`` samples the same aperture with a
  linear edge ramp instead).
- Köhler illumination sampled as plane waves on the lattice (Abbe's method, paper Eq. 2): source
  points over the condenser disk |w| ≤ NA_c/λ, each weighted by the area of its cell in the disk.

Frequencies are in cycles/µm, distances in µm; lattice arrays are in FFT order unless said.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft
from scipy.spatial import cKDTree

from napari_ssdpc.physics.pupil import eta

__all__ = [
    "apply_transfer",
    "cell_fraction",
    "defocus_factor",
    "disk_fraction",
    "in_subaperture",
    "kohler_source",
    "objective_pupil_cells",
    "propagate",
    "propagator",
    "subaperture_windows",
    "transfer_function",
]


# ----------------------------------------------------------------------- propagation
def defocus_factor(eta_values, d_um: float, eta0: float = 0.0) -> np.ndarray:
    """exp(i2π d [Re η − η0]) · exp(−2π |d| Im η): propagation over ``d_um`` from η(u).

    The propagating part is the phase of the angular spectrum (paper Eq. 6); evanescent
    components (Im η > 0) decay for either sign of d, so back-propagation never amplifies them.

    Parameters
    ----------
    eta_values : ndarray, complex, any shape
        η(u), cycles/µm (from :func:`napari_ssdpc.physics.pupil.eta`).
    d_um : float
        Distance, µm (> 0: toward the objective).
    eta0 : float
        Reference axial frequency whose phase is dropped (a tilted wave's η(w)), cycles/µm.

    Returns
    -------
    ndarray, complex128, shape of ``eta_values``
        The transfer function, dimensionless.
    """
    e = np.asarray(eta_values)
    return np.exp(2j * np.pi * d_um * (e.real - eta0)) * np.exp(-2 * np.pi * abs(d_um) * e.imag)


def transfer_function(
    u2, d_um: float, n_medium: float, wavelength_um: float, *, eta0: float = 0.0, cut_evanescent: bool = False
) -> np.ndarray:
    """Angular-spectrum transfer function H_d(u) = exp(i2π d [η(u) − η0]), η = sqrt((n/λ)² − |u|²).

    Parameters
    ----------
    u2 : array_like
        Squared lateral frequency |u|², (cycles/µm)².
    d_um : float
        Distance, µm (> 0: toward the objective).
    n_medium : float
        Refractive index of the medium.
    wavelength_um : float
        Vacuum wavelength, µm.
    eta0 : float
        Reference axial frequency whose phase is dropped, cycles/µm (e.g. n/λ: no constant phase).
    cut_evanescent : bool
        True: H = 0 for |u| ≥ n/λ; False: evanescent components decay as exp(−2π |d| Im η).

    Returns
    -------
    ndarray, complex128, shape of ``u2``
        H_d, dimensionless.
    """
    h = defocus_factor(eta(u2, n_medium, wavelength_um), d_um, eta0)
    if cut_evanescent:
        return np.where(np.asarray(u2) < (n_medium / wavelength_um) ** 2, h, 0.0)
    return h


def propagator(
    ny: int,
    nx: int,
    dx_um: float,
    d_um: float,
    wavelength_um: float,
    n_medium: float,
    tilt=(0.0, 0.0),
    dtype=np.complex64,
) -> np.ndarray:
    """H_d on the FFT grid of a (ny, nx) field of spacing ``dx_um``, for the envelope of a tilted wave.

    The field is the envelope V of U = V exp(i2π w·x) (w = ``tilt``), so grid frequency u stands
    for u + w: H = exp(i2π d [η(u + w) − η(w)]) (the constant phase of the tilted wave dropped).

    Parameters
    ----------
    ny, nx : int
        Field shape, samples.
    dx_um : float
        Sample spacing, µm.
    d_um : float
        Distance, µm (> 0: toward the objective).
    wavelength_um : float
        Vacuum wavelength, µm.
    n_medium : float
        Refractive index of the medium.
    tilt : (float, float)
        w (x, y), cycles/µm.
    dtype : numpy dtype
        Complex dtype of the result.

    Returns
    -------
    ndarray, (ny, nx)
        H_d in FFT order, ``dtype``.
    """
    uy = np.fft.fftfreq(ny, dx_um)[:, None] + tilt[1]
    ux = np.fft.fftfreq(nx, dx_um)[None, :] + tilt[0]
    e0 = float(eta(tilt[0] ** 2 + tilt[1] ** 2, n_medium, wavelength_um).real)
    return transfer_function(ux * ux + uy * uy, d_um, n_medium, wavelength_um, eta0=e0).astype(dtype)


def apply_transfer(field, h) -> np.ndarray:
    """Filter a field (or a batch of fields) by a transfer function: F⁻¹{F{field} · h}.

    Parameters
    ----------
    field : ndarray, complex, (..., ny, nx)
        Field(s) on the grid of ``h``.
    h : ndarray, complex, (ny, nx)
        Transfer function in FFT order.

    Returns
    -------
    ndarray, complex, (..., ny, nx)
        The filtered field(s).
    """
    return sfft.ifft2(sfft.fft2(field, workers=-1) * h, workers=-1)


def propagate(field, d_um: float, dx_um: float, wavelength_um: float, n_medium: float, tilt=(0.0, 0.0)):
    """Angular-spectrum propagation of a field, or a batch of fields, over ``d_um`` in a medium.

    Spectrum x exp(+i2π d [η(u + w) − η(w)]) (:func:`propagator`); evanescent components are
    damped for either sign of d. ``tilt`` = w: the field is the envelope V of U = V exp(i2π w·x);
    for w = 0 it is the field itself (the constant phase exp(i2π d η(0)) is dropped).

    Parameters
    ----------
    field : ndarray, complex, (..., ny, nx)
        The field(s) (or envelope(s) V for a non-zero ``tilt``), sampled every ``dx_um``.
    d_um, dx_um, wavelength_um, n_medium, tilt
        Distance (µm, > 0: toward the objective), sampling (µm), vacuum wavelength (µm), medium
        index and w (x, y) in cycles/µm, as for :func:`propagator`.

    Returns
    -------
    ndarray, complex, (..., ny, nx)
        The propagated field(s), dtype of ``field`` if complex, else complex128.
    """
    field = np.asarray(field)
    ny, nx = field.shape[-2:]
    out = apply_transfer(field, propagator(ny, nx, dx_um, d_um, wavelength_um, n_medium, tilt))
    return out.astype(field.dtype if np.iscomplexobj(field) else np.complex128, copy=False)


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


def in_subaperture(ux, uy, u_k, rho: float, cutoff: float) -> np.ndarray:
    """Whether u lies in the sub-aperture A_k = P_obj · circ(|u − u_k| ≤ ρ) (paper Eq. 2).

    Parameters
    ----------
    ux, uy : ndarray
        Frequencies (broadcastable), cycles/µm.
    u_k : array_like, (2,)
        The lenslet's sub-aperture centre (x, y), cycles/µm.
    rho : float
        Sub-aperture radius ρ, cycles/µm.
    cutoff : float
        Objective cut-off NA/λ, cycles/µm.

    Returns
    -------
    ndarray, bool
        The broadcast shape of ``ux`` and ``uy``.
    """
    return ((ux - u_k[0]) ** 2 + (uy - u_k[1]) ** 2 <= rho * rho) & (ux * ux + uy * uy <= cutoff * cutoff)


def lenslet_source_weights(
    w, spacing: float, radius: float, u_centres, rho: float, cutoff: float, supersample=8, max_samples=250_000
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
    u_centres : array_like, (K, 2)
        Sub-aperture centres u_k (x, y), cycles/µm.
    rho : float
        Sub-aperture radius ρ, cycles/µm.
    cutoff : float
        Objective cut-off NA/λ, cycles/µm.
    supersample : int
        Samples of the disk per lattice step.
    max_samples : int
        At most this many samples of the disk (fewer per step for a fine lattice).

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
    v = np.stack([sx[keep], sy[keep]], axis=1)
    out = np.zeros((len(w), len(u_centres)))
    for k, u_k in enumerate(np.asarray(u_centres, float)):
        bright_v = in_subaperture(v[:, 0], v[:, 1], u_k, rho, cutoff)
        bright_w = in_subaperture(w[:, 0], w[:, 1], u_k, rho, cutoff)
        for side in (True, False):
            pts = np.flatnonzero(bright_w == side)
            if not len(pts):  # no point on this side: the nearest of any side carries it
                pts = np.arange(len(w))
            samples = v[bright_v == side]
            if len(samples):
                _, nearest = cKDTree(w[pts]).query(samples)
                out[:, k] += np.bincount(pts[nearest], minlength=len(w)) * h * h
    return out


def objective_pupil_cells(u2, cutoff: float, du: float) -> np.ndarray:
    """The objective pupil on a lattice of step ``du``: every cell that touches |u| ≤ NA/λ passes.

    Its exact (area-weighted) edge is applied by the sub-apertures (:func:`subaperture_windows`).

    Parameters
    ----------
    u2 : ndarray
        |u|² of the lattice, (cycles/µm)².
    cutoff : float
        NA/λ, cycles/µm.
    du : float
        Lattice step, cycles/µm.

    Returns
    -------
    ndarray, float32, shape of ``u2``
        1 or 0.
    """
    return (u2 <= (cutoff + du / math.sqrt(2)) ** 2).astype(np.float32)


def subaperture_windows(u_centres, rho: float, cutoff: float, du: float, nc: int, supersample: int = 8):
    """Each lenslet's sub-aperture A_k on an ``nc`` x ``nc`` crop of the lattice around u_k.

    The crop is centred on the lattice point nearest u_k; each cell passes the amplitude
    sqrt(area fraction of the cell in A_k), so |A_k|² integrates to the sub-aperture's area.

    Parameters
    ----------
    u_centres : array_like, (K, 2)
        Sub-aperture centres u_k (x, y), cycles/µm.
    rho : float
        Sub-aperture radius ρ, cycles/µm.
    cutoff : float
        Objective cut-off NA/λ, cycles/µm.
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
    apertures : ndarray, float32, (K, nc, nc)
        Amplitude of A_k on the crop (rows y, columns x), in [0, 1].
    """
    off = np.arange(nc) - nc // 2
    centres, apert = [], []
    for u_k in u_centres:
        c = np.rint(np.asarray(u_k) / du).astype(int)
        ux, uy = (c[0] + off) * du, (c[1] + off) * du

        def inside(sx, sy, u_k=u_k):
            return in_subaperture(sx, sy, u_k, rho, cutoff)

        centres.append(c)
        apert.append(np.sqrt(cell_fraction(inside, ux[None, :], uy[:, None], du, supersample)))
    return np.array(centres), np.array(apert, dtype=np.float32)


# ---------------------------------------------------------------------------- source
def kohler_source(radius: float, du: float, step: int = 2, supersample: int = 64):
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
    m = int(math.ceil(radius / (h * du))) + 1
    i = np.arange(-m, m + 1)
    gx, gy = np.meshgrid(i, i)
    ix, iy = gx.ravel(), gy.ravel()
    wgt = disk_fraction(ix * h * du, iy * h * du, radius, h * du, supersample) * (h * du) ** 2
    keep = wgt > 0
    idx = np.stack([ix[keep] * h, iy[keep] * h], axis=1)
    return idx, idx * du, wgt[keep]
