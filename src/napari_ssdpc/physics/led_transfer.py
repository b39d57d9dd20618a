"""Transfer functions of conventional DPC: half of the illumination disk per image, the whole
objective pupil, and for a z-stack each image at its own focal plane.

Each image (pattern p, focal plane f) is a view of the general weak-object model of
:mod:`.transfer` (paper Eqs. 2-4): source S_p(w) the half of the disk |w| ≤ NA_ill/λ on the side
of its angle θ_p (w·(cos θ_p, sin θ_p) ≥ 0), pupil P(w) = circ(|w| ≤ NA/λ), and a slab at depth z
seen defocused by z − z_f (Chen, Tian and Waller's 3D DPC, Biomed. Opt. Express 7, 3940 (2016):
the 3D WOTF of a z-stack is the stack of these 2D transfer functions over the slabs). The views
are ordered pattern by pattern, each pattern's focal planes in their order: view k = p·F + f.
"""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.apertures import disk_fraction
from napari_ssdpc.physics.multislice_source import disk_points
from napari_ssdpc.physics.pupil import eta, soft_disk
from napari_ssdpc.physics.transfer import fft_indices, weak_object_transfer_functions, zero_padded
from napari_ssdpc.settings.dpc_optics import DpcOptics

__all__ = ["LedPatterns", "half_plane", "led_source_points"]


def half_plane(wx, wy, angles_deg, step: float) -> np.ndarray:
    """The share of each source sample in each pattern's half: the side of the disk its angle points
    to (w·(cos θ, sin θ) ≥ 0), a linear ramp one sample wide across the edge line (a sample on it
    counts half).

    Parameters
    ----------
    wx, wy : array_like
        Source frequencies, cycles/µm (broadcastable).
    angles_deg : sequence of float
        The patterns' angles, degrees (``patterns_deg``).
    step : float
        The samples' spacing, cycles/µm.

    Returns
    -------
    ndarray, (P, ...)
        In [0, 1], one leading entry per pattern.
    """
    wx, wy = np.broadcast_arrays(np.asarray(wx, float), np.asarray(wy, float))
    t = np.radians(np.asarray(angles_deg, float)).reshape(-1, *([1] * wx.ndim))
    return np.clip(0.5 + (wx * np.cos(t) + wy * np.sin(t)) / step, 0.0, 1.0)


class LedPatterns:
    """The half-disk patterns of a DPC microscope as a
    :class:`~napari_ssdpc.reconstruction.forward.TransferFunctions`.

    Parameters
    ----------
    optics : DpcOptics
    shape : (int, int)
        Image grid (ny, nx).

    Attributes
    ----------
    i0 : ndarray, float, (K,)
        Each view's direct light in the model, ∫ S_p |P|² / ∫ S_p (1 where the disk lies inside the pupil).
    m_out : (int, int)
        The band grid (my, mx): frequencies up to (NA + NA_ill)/λ, unshifted FFT order.
    """

    def __init__(self, optics: DpcOptics, shape):
        self.optics = optics
        self.shape = tuple(int(n) for n in shape)
        du = tuple(1.0 / (n * optics.pixel_um) for n in self.shape)
        step = math.sqrt(du[0] * du[1])
        m_in = tuple(2 * int(math.ceil(optics.cutoff / d)) + 4 for d in du)
        reach = optics.cutoff + optics.source_radius
        self.m_out = tuple(min(n, 2 * int(math.ceil(reach / d)) + 3) for n, d in zip(self.shape, du))
        wy = (fft_indices(m_in[0]) * du[0])[:, None]
        wx = (fft_indices(m_in[1]) * du[1])[None, :]
        disk = soft_disk(np.hypot(wx, wy), optics.source_radius, step)
        self.src = disk * half_plane(wx, wy, optics.patterns_deg, step)  # (P, My, Mx)
        self.pupil = soft_disk(np.hypot(wx, wy), optics.cutoff, step).astype(complex)
        self.eta = eta(wx**2 + wy**2, optics.medium_index, optics.wavelength_um).real
        self.norm = self.src.sum(axis=(-2, -1))  # each pattern's source power
        if np.any(self.norm <= 0):
            raise SsdpcError("a pattern lights no source point; check illumination_na and patterns_deg")
        i0 = np.sum(self.src * np.abs(self.pupil), axis=(-2, -1)) / self.norm
        self.focal = np.asarray(optics.focal_planes_um, float)
        self.i0 = np.repeat(i0, len(self.focal))  # view k = p·F + f

    @property
    def n_views(self) -> int:
        """K = patterns x focal planes."""
        return len(self.i0)

    def band(self, zs):
        """(H_abs, H_phase) (Z, K, my, mx) of slabs at the depths ``zs`` on the band grid.

        Parameters
        ----------
        zs : ndarray, (Z,)
            Depths of the slabs, µm.

        Returns
        -------
        h_abs, h_phase : ndarray, complex64, (Z, K, my, mx)
            Unshifted FFT order; view k = p·F + f sees the slab defocused by z − z_f.
        """
        zs = np.atleast_1d(np.asarray(zs, float))
        n_p, n_f = len(self.src), len(self.focal)
        h_abs = np.empty((len(zs), n_p, n_f, *self.m_out), np.complex64)
        h_phase = np.empty_like(h_abs)
        for p in range(n_p):
            for f, zf in enumerate(self.focal):
                a, ph = weak_object_transfer_functions(
                    self.src[p], self.pupil, list(zs - zf), self.eta, self.m_out, float(self.norm[p])
                )
                h_abs[:, p, f], h_phase[:, p, f] = a, ph
        shape = (len(zs), n_p * n_f, *self.m_out)
        return h_abs.reshape(shape), h_phase.reshape(shape)

    def embed(self, h):
        """Band grid -> image grid (zeros beyond the band, where the transfer functions vanish).

        Parameters
        ----------
        h : ndarray, (..., my, mx)

        Returns
        -------
        ndarray, (..., ny, nx)
            Unshifted FFT order.
        """
        return h if h.shape[-2:] == self.shape else zero_padded(h, self.shape)


def led_source_points(optics: DpcOptics, h: float, q: int):
    """The illumination of the multislice model of a DPC stack: points over the illumination disk on
    a lattice of step h, each standing for q x q sub-points, weighted for every view by the part of
    its sub-cell in the disk and in the view's half (a sub-point on the half's edge line counts half).

    Parameters
    ----------
    optics : DpcOptics
    h : float
        Lattice step, cycles/µm.
    q : int
        Sub-points per point and axis.

    Returns
    -------
    w : ndarray, (S, 2)
        The points, cycles/µm.
    w_sub : ndarray, (S, Q, 2)
        Their sub-points (Q = q²).
    wgt : ndarray, (S, Q, K)
        Every sub-point's weight for every view (view k = p·F + f).
    """
    w, w_sub = disk_points(optics.source_radius, h, q)
    step = h / q
    cell = disk_fraction(w_sub[..., 0], w_sub[..., 1], optics.source_radius, step) * step * step
    halves = np.moveaxis(half_plane(w_sub[..., 0], w_sub[..., 1], optics.patterns_deg, step), 0, -1)  # (S, Q, P)
    wgt = np.repeat(halves * cell[..., None], len(optics.focal_planes_um), axis=-1)
    return w, w_sub, wgt
