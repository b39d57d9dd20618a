"""The multislice model's region and its source: a square region of the views' grid, the Köhler
source points with their sub-points and per-lenslet weights, and each (point, lenslet) pair's crop
of the exit spectrum (:class:`~napari_ssdpc.physics.views_multislice.ViewsMultislice`).

Frequencies are in cycles/µm, lengths in µm.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.apertures import disk_fraction, kohler_source, lenslet_source_weights
from napari_ssdpc.physics.pupil import Pupil, eta
from napari_ssdpc.physics.waves import defocus_factor
from napari_ssdpc.settings.optics import Optics

__all__ = [
    "CropInterpolation",
    "disk_points",
    "even_fast",
    "even_planes",
    "fits_memory",
    "lenslet_crops",
    "lit_views",
    "model_bytes",
    "slab_propagators",
    "source_quadrature",
    "square_roi",
]


def even_fast(m: int) -> int:
    """The smallest even FFT-friendly size >= ``m``.

    Parameters
    ----------
    m : int

    Returns
    -------
    int
    """
    m = sfft.next_fast_len(max(int(m), 2))
    while m % 2:
        m = sfft.next_fast_len(m + 1)
    return m


def square_roi(x_um, y_um, centre_um=(0.0, 0.0), side_um: float = 40.0) -> tuple[slice, slice]:
    """A square region of the views' grid around ``centre_um``, of an even FFT-friendly side.

    Parameters
    ----------
    x_um, y_um : array_like, (w,), (h,)
        The views' grid (pixel centres), µm from the optical axis.
    centre_um : (float, float)
        (x, y) of the region's centre, µm.
    side_um : float
        Smallest side, µm: the sample plus the margin its scattered light needs.

    Returns
    -------
    rows, cols : slice
        The region on the views' grid (equal lengths), shifted to lie inside it.
    """
    x, y = np.asarray(x_um, float), np.asarray(y_um, float)
    px = float(x[1] - x[0])
    side = even_fast(int(math.ceil(side_um / px)))
    if side > min(len(x), len(y)):
        side = min(len(x), len(y)) // 2 * 2
    out = []
    for c, grid in ((centre_um[1], y), (centre_um[0], x)):
        i0 = int(np.argmin(np.abs(grid - c))) - side // 2
        i0 = min(max(i0, 0), len(grid) - side)
        out.append(slice(i0, i0 + side))
    return out[0], out[1]


def source_quadrature(optics: Optics, pupil: Pupil, lenslets, h: float, q: int, edge_weights: bool = True):
    """Source points over the condenser disk (paper Eq. 2) on a square lattice of step h, each
    standing for q x q sub-points of its cell, with every sub-point's weight for every lenslet.

    The multislice runs once per point; its exit field stands for the sub-points of its cell, which
    the exit propagation, the pupil and the sub-apertures see at their own tilt.

    Parameters
    ----------
    optics : Optics
    pupil : Pupil
    lenslets : list of Lenslet, or ndarray (K, 2)
        The views' lenslets (their own sub-apertures), or bare sub-aperture centres, cycles/µm.
    h : float
        Lattice step of the points, cycles/µm.
    q : int
        Sub-points per point and axis.
    edge_weights : bool
        Weight the sub-points per lenslet so that each view's bright-field area is exact
        (:func:`~napari_ssdpc.physics.apertures.lenslet_source_weights`); otherwise every sub-point
        carries its own cell of the disk for every lenslet.

    Returns
    -------
    w : ndarray, (S, 2)
        The points, cycles/µm.
    w_sub : ndarray, (S, Q, 2)
        Their sub-points (Q = q²).
    wgt : ndarray, (S, Q, K)
        The weight of every sub-point for every lenslet.
    """
    c = optics.source_centre  # the condenser disk's centre
    w, w_sub = disk_points(optics.source_radius, h, q, c)
    flat_sub = w_sub.reshape(-1, 2)
    if edge_weights:  # (S·Q, K): each lenslet's bright-field edge sampled finely
        wgt = lenslet_source_weights(flat_sub, h / q, optics.source_radius, lenslets, pupil, centre=c)
    else:
        cell = disk_fraction(flat_sub[:, 0] - c[0], flat_sub[:, 1] - c[1], optics.source_radius, h / q) * (h / q) ** 2
        wgt = np.repeat(cell[:, None], len(lenslets), axis=1)
    return w, w_sub, wgt.reshape(len(w), q * q, len(lenslets))


def disk_points(radius: float, h: float, q: int, centre=(0.0, 0.0)):
    """Points over a source disk on a square lattice of step h, each standing for the q x q
    sub-points of its cell.

    Parameters
    ----------
    radius : float
        The disk's radius, cycles/µm.
    h : float
        Lattice step, cycles/µm.
    q : int
        Sub-points per point and axis.
    centre : (float, float)
        The disk's centre, cycles/µm.

    Returns
    -------
    w : ndarray, (S, 2)
        The points, cycles/µm.
    w_sub : ndarray, (S, Q, 2)
        Their sub-points (Q = q²), at the centres of the q x q sub-cells.
    """
    if q < 1:
        raise SsdpcError("source_subsamples must be a positive integer")
    _, w, _ = kohler_source(radius, h, 1, centre=centre)
    t = ((np.arange(q) + 0.5) / q - 0.5) * h
    return w, w[:, None] + np.stack(np.meshgrid(t, t), axis=-1).reshape(1, q * q, 2)


def lenslet_crops(w, w_sub, u_k, du: float, m: int, n: int):
    """For every (point, lenslet) pair, an m x m crop of the exit spectrum around u_k − w_j.

    Parameters
    ----------
    w : ndarray, (S, 2)
        Source points, cycles/µm.
    w_sub : ndarray, (S, Q, 2)
        Their sub-points.
    u_k : ndarray, (K, 2)
        Sub-aperture centres.
    du : float
        The grid's frequency step, cycles/µm.
    m : int
        Crop side.
    n : int
        The grid's side.

    Returns
    -------
    ex, ey : ndarray, int, (S, K, m)
        Envelope-grid indices of the crops (unwrapped).
    ux, uy : ndarray, (S, Q, K, m)
        Absolute frequency of every crop index for every sub-point.
    inx, iny : ndarray, bool, (S, 1, K, m)
        Inside the grid's band.
    """
    off = np.arange(m) - m // 2
    c = np.rint((u_k[None] - w[:, None]) / du).astype(int)  # (S, K, 2): crop centres, lattice units
    ex, ey = c[..., 0, None] + off, c[..., 1, None] + off
    ux = w_sub[:, :, None, 0, None] + ex[:, None] * du
    uy = w_sub[:, :, None, 1, None] + ey[:, None] * du
    inx = ((ex >= -(n // 2)) & (ex < n - n // 2))[:, None]
    iny = ((ey >= -(n // 2)) & (ey < n - n // 2))[:, None]
    return ex, ey, ux, uy, inx, iny


class CropInterpolation:
    """E: a band-limited intensity on the m x m crop grid -> the views' nv x nv pixels (Fourier
    interpolation, averaged over the sensor pixel by its sinc), and its exact transpose.

    Parameters
    ----------
    m, nv : int
        Sides of the crop grid and of the views' region.
    pixel_cycles : float
        The view pixel times the crop grid's frequency step (the sinc's argument per frequency index).
    pixel_integration : bool
        Average over the sensor pixel; otherwise sample.
    bk : Backend
    rdtype : numpy dtype
        Real dtype of the results.
    """

    def __init__(self, m: int, nv: int, pixel_cycles: float, pixel_integration: bool, bk, rdtype):
        fm = np.fft.fftfreq(m, 1.0 / m).astype(int)
        pix = np.sinc(pixel_cycles * fm) if pixel_integration else np.ones(m)
        self.m, self.nv, self.bk, self.rdtype = m, nv, bk, rdtype
        self._band = bk.xp.asarray(fm % nv)
        self._pix = bk.xp.asarray((pix[:, None] * pix[None, :]).astype(rdtype))

    def __call__(self, im):
        """E of an intensity.

        Parameters
        ----------
        im : ndarray, (K, m, m)

        Returns
        -------
        ndarray, (K, nv, nv)
        """
        nv, m = self.nv, self.m
        spec = self.bk.fft2(im) * self._pix
        out = self.bk.xp.zeros((im.shape[0], nv, nv), spec.dtype)
        out[:, self._band[:, None], self._band[None, :]] = spec
        return (self.bk.ifft2(out).real * (nv * nv / (m * m))).astype(self.rdtype)

    def adjoint(self, grad):
        """Eᵀ of a gradient on the views' pixels.

        Parameters
        ----------
        grad : ndarray, (K, nv, nv)

        Returns
        -------
        ndarray, (K, m, m)
        """
        nv = self.nv
        spec = self.bk.fft2(grad)[:, self._band[:, None], self._band[None, :]] / (nv * nv)
        return (self.bk.ifft2(spec * self._pix).real * (nv * nv)).astype(self.rdtype)


def even_planes(z_um, dz_um=None) -> tuple[np.ndarray, float]:
    """The model's planes and their spacing, checked to increase evenly.

    Parameters
    ----------
    z_um : array_like, (Z,)
        Plane centres, µm.
    dz_um : float, optional
        Spacing, µm (needed for a single plane).

    Returns
    -------
    z : ndarray, (Z,)
    dz : float
    """
    z = np.atleast_1d(np.asarray(z_um, float))
    dz = float(dz_um) if dz_um is not None else float(z[1] - z[0]) if len(z) > 1 else 0.0
    if dz <= 0 or (len(z) > 1 and np.ptp(np.diff(z)) > 1e-6 * dz):
        raise SsdpcError("z_um must increase evenly (or give dz_um for a single plane)")
    return z, dz


def slab_propagators(w, n: int, dx: float, delta: float, medium_index: float, wavelength_um: float) -> np.ndarray:
    """Propagation through one slab, per source point: exp(i2π δ [η(u + w) − η(w)]) (paper Eq. 6).

    Parameters
    ----------
    w : ndarray, (S, 2)
        Source points' spatial frequencies, 1/µm.
    n : int
        Model grid side, px.
    dx : float
        Model pixel, µm.
    delta : float
        Slab thickness, µm.
    medium_index, wavelength_um : float

    Returns
    -------
    ndarray, complex, (S, n, n)
        On the FFT grid of the model.
    """
    f = np.fft.fftfreq(n, dx)
    u2 = (f[None, None, :] + w[:, 0, None, None]) ** 2 + (f[None, :, None] + w[:, 1, None, None]) ** 2
    e = eta(u2, medium_index, wavelength_um)
    e0 = eta(np.sum(w * w, axis=1), medium_index, wavelength_um).real[:, None, None]
    return defocus_factor(e, delta) * np.exp(-2j * np.pi * delta * e0)


def lit_views(i0: np.ndarray) -> np.ndarray:
    """The sample-free intensity of every view, refused where a view receives no direct light.

    Parameters
    ----------
    i0 : ndarray, (K,)
        Mean sample-free intensity per view.

    Returns
    -------
    ndarray, (K,)
        ``i0`` itself.
    """
    dark = np.flatnonzero(i0 <= 1e-6 * i0.max()).tolist()
    if dark:
        raise SsdpcError(
            f"views {dark} receive no direct light from the model's source points: keep only lit "
            "lenslets, or make source_spacing_na smaller"
        )
    return i0


def model_bytes(
    sources: int, subsources: int, views: int, n: int, m: int, slabs: int, chunk: int, cdtype, memory_mb: float
) -> int:
    """Peak memory of a multislice misfit with its gradient, bytes: the fields kept between the passes
    (up to ``memory_mb``), every sub-point's view fields, the kept crop kernels, the propagators and
    one chunk's temporaries.

    Parameters
    ----------
    sources, subsources : int
        Source points and sub-points per point.
    views : int
        Views (lenslets or images).
    n, m : int
        The model grid's side and the crops' side, samples.
    slabs : int
        Multislice slabs (planes x substeps).
    chunk : int
        Source points propagated at a time.
    cdtype : numpy dtype
        Complex dtype of the fields.
    memory_mb : float
        Largest memory for the kept fields, MiB.

    Returns
    -------
    int
    """
    c = np.dtype(cdtype).itemsize
    s, q = sources, subsources
    pairs = s * q * views * m * m * c
    fields = min(slabs * s * n * n * c, memory_mb * 2**20)
    kernels = pairs if pairs <= memory_mb * 2**18 else 0
    temporaries = chunk * (4 * q * views * m * m + 6 * n * n) * c
    return int(fields + pairs + kernels + 3 * s * n * n * c + temporaries)


def fits_memory(bytes_needed: int, max_bytes: int | None, side_um: float, planes: int) -> None:
    """Refuse a model larger than the free memory, with what to change.

    Parameters
    ----------
    bytes_needed : int
        The model's estimated size.
    max_bytes : int or None
        Free memory; None: not checked.
    side_um : float
        The region's side, µm.
    planes : int
    """
    if max_bytes is not None and bytes_needed > max_bytes:
        raise SsdpcError(
            f"the multislice model of a {side_um:.0f} µm region with {planes} planes needs about "
            f"{bytes_needed / 2**30:.1f} GiB but {max_bytes / 2**30:.1f} GiB are free: choose a smaller "
            "region (--roi, or a Shapes layer in napari) or fewer source points (a larger source_spacing_na)"
        )
