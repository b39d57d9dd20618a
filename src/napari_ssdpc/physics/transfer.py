"""Weak-object transfer functions for a general source S and pupil P (paper Eqs. 2-4, docs/conventions.md).

Intensity model, first order in μ and φ, with o = exp(−μ + iφ) ≈ 1 − μ + iφ, plane waves
exp(+i2π w·x) and a source normalised by its power ∫S:

    Ĩ(u) = I0·δ(u) − H_abs(u)·μ̃(u) + H_phase(u)·φ̃(u)

    W(u)       = ∫ S(w) P(w+u) P*(w) exp(i2πz[η(w+u) − η(w)]) d²w / ∫ S     (the WOTF)
    I0         = W(0) = ∫ S |P|² / ∫ S
    H_abs(u)   = W(u) + W*(−u)           H_abs(0) = 2 I0 (2 for a full disk inside the pupil)
    H_phase(u) = i [W(u) − W*(−u)]       imaginary and odd in focus (real S and P)

so absorption lowers the intensity by H_abs·μ and a phase adds H_phase·φ. The factor i is the one
paper Eq. 4 leaves out when it writes H_phi = WOTF*(u) − WOTF(−u) (docs/conventions.md).

Two models give the transfer functions of each half (up, down, left, right) of paper Eq. 5:
- 'paper': half of the condenser disk as the source, the full objective pupil (paper Eq. 4).
- 'lenslet': the full condenser disk and the sub-apertures of the lenslets of that half; the EIs
  of the lenslets add, so H_half = Σ_k H_k and I0_half = Σ_k I0_k (docs/conventions.md).
The lenslet at a_y < 0 ("up") sees frequencies u_y > 0 (u_k = −a/(λ f_obj m_r)), so the
'paper' half-source of "up" is w_y > 0, and likewise "left" is w_x > 0.

For DPC = (I1 − I2)/(I1 + I2) the first-order transfer function is
    H_DPC = 2 (I0_2 H_1 − I0_1 H_2) / (I0_1 + I0_2)²,
which is H_1/I0_1 when the halves mirror each other: the phase TF of one half normalised by that
half's own background, not by the full aperture and not doubled (docs/conventions.md).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import cpu
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.pupil import Pupil, axial_frequency, soft_disk, subaperture_pupil
from napari_ssdpc.settings.optics import Optics

__all__ = [
    "LensletSetup",
    "fft_indices",
    "lenslet_transfer_functions",
    "paper_transfer_functions",
    "weak_object_transfer_functions",
    "zero_padded",
]


# ------------------------------------------------------------ general (S, P)
def weak_object_transfer_functions(source, pupil, z_um=0.0, eta=None, out_shape=None, norm=None):
    """(H_abs, H_phase) of a source S(w) and pupil P(w) by FFT correlation (paper Eqs. 2-4).

    Parameters
    ----------
    source : ndarray, float, (..., My, Mx)
        S(w), real, on a frequency grid in unshifted FFT order: sample j sits at w = w0 + j·du.
    pupil : ndarray, complex, (..., My, Mx)
        P(w) on the same grid.
    z_um : float or sequence of float
        Defocus, µm (z > 0 farther from the objective).
    eta : ndarray, optional
        η(w) on that grid, cycles/µm; needed when ``z_um`` is not 0.
    out_shape : (int, int), optional
        Output grid (differences u = m·du, unshifted FFT order); default the input grid.
    norm : float, optional
        Source power ∫S (default the sum of ``source``).

    Returns
    -------
    h_abs, h_phase : ndarray, complex64
        (..., ny, nx) for a scalar z, (Z, ..., ny, nx) for a sequence. The correlation is linear
        (zero padded), not circular.
    """
    s = np.asarray(source, dtype=float)
    p = np.asarray(pupil, dtype=complex)
    if s.shape != p.shape or s.ndim < 2:
        raise SsdpcError(f"source {s.shape} and pupil {p.shape} must share one 2D frequency grid")
    zs = np.atleast_1d(np.asarray(z_um, dtype=float))
    if eta is None and np.any(zs != 0):
        raise SsdpcError("defocus needs eta = η(w) on the pupil grid; pass eta=axial_frequency(...)")
    norm = float(s.sum()) if norm is None else float(norm)
    if not norm > 0:
        raise SsdpcError("the source is empty; give a source with positive power (condenser_na > 0)")
    out_shape = tuple(s.shape[-2:]) if out_shape is None else tuple(out_shape)
    pad = tuple(sfft.next_fast_len(m + n) for m, n in zip(s.shape[-2:], out_shape))
    s_pad = zero_padded(s, pad)
    p_pad = zero_padded(p, pad)
    eta_pad = None if eta is None else zero_padded(np.broadcast_to(eta, s.shape), pad)
    iy, ix = (fft_indices(n) for n in out_shape)
    h_abs, h_phase = [], []
    for z in zs:
        q = p_pad if z == 0 else p_pad * np.exp(2j * np.pi * z * eta_pad)
        # W(m) = Σ_j S_j Q_{j+m} Q*_j = IFFT[conj(FFT(S·Q)) · FFT(Q)]
        w = cpu().ifft2(np.conj(cpu().fft2(s_pad * q)) * cpu().fft2(q)) / norm
        w_pos = w[..., (iy % pad[0])[:, None], (ix % pad[1])[None, :]]
        w_neg = np.conj(w[..., (-iy % pad[0])[:, None], (-ix % pad[1])[None, :]])
        h_abs.append((w_pos + w_neg).astype(np.complex64))
        h_phase.append((1j * (w_pos - w_neg)).astype(np.complex64))
    if np.ndim(z_um) == 0:
        return h_abs[0], h_phase[0]
    return np.stack(h_abs), np.stack(h_phase)


def fft_indices(n: int) -> np.ndarray:
    """Integer frequency indices of an unshifted FFT axis.

    Parameters
    ----------
    n : int
        The axis' length.

    Returns
    -------
    ndarray of int, (n,)
        0, 1, ..., then the negative indices.
    """
    return np.rint(sfft.fftfreq(n) * n).astype(int)


def zero_padded(a, shape) -> np.ndarray:
    """An unshifted-order array zero-padded into a larger unshifted-order grid (last two axes).

    Parameters
    ----------
    a : ndarray, (..., my, mx)
    shape : (int, int)
        The larger grid (ny, nx).

    Returns
    -------
    ndarray, (..., ny, nx)
    """
    iy = fft_indices(a.shape[-2]) % shape[0]
    ix = fft_indices(a.shape[-1]) % shape[1]
    out = np.zeros(a.shape[:-2] + tuple(shape), dtype=a.dtype)
    out[..., iy[:, None], ix[None, :]] = a
    return out


# ------------------------------------------------------------ the two models
def _frequency_steps(shape, pixel_um):
    return tuple(1.0 / (n * pixel_um) for n in shape)


def lenslet_transfer_functions(optics: Optics, lenslets, shape, pixel_um, z_um=0.0, oversample=1):
    """Weak-object transfer functions of each lenslet: full condenser disk, sub-aperture P_obj·circ_k.

    Parameters
    ----------
    optics : Optics
    lenslets : list of Lenslet
    shape : (int, int)
        View grid (ny, nx).
    pixel_um : float
        View pixel in object space, µm.
    z_um : float or sequence of float
        Defocus, µm.
    oversample : int
        Pupil sampling r times finer than the output grid (r = 1 is within 0.1% of the exact
        integral for the paper's optics).

    Returns
    -------
    h_abs, h_phase : ndarray, complex64, (K, ny, nx) or (K, Z, ny, nx)
        Unshifted FFT order.
    i0 : ndarray, float, (K,)
        Each lenslet's direct-light background (fraction of the condenser light).
    """
    setup = LensletSetup(optics, lenslets, shape, pixel_um, oversample)
    zs = np.atleast_1d(np.asarray(z_um, dtype=float))
    h_abs, h_phase = (setup.embed(h) for h in setup.band(zs))  # (Z, K, ny, nx)
    if np.ndim(z_um) == 0:
        return h_abs[0], h_phase[0], setup.i0
    return np.swapaxes(h_abs, 0, 1), np.swapaxes(h_phase, 0, 1), setup.i0


class LensletSetup:
    """Sub-aperture grids of every lenslet, centred on u_k, and the output band |u| <= 2ρ.

    Built once per set of lenslets; :meth:`band` then gives the transfer functions of any
    depths on the band grid (the only frequencies an EI's intensity can hold), and
    :meth:`embed` places them on the full image grid.

    Parameters
    ----------
    optics : Optics
    lenslets : sequence of Lenslet
        The lit lenslets (K of them).
    shape : (int, int)
        Image grid (ny, nx) of the output transfer functions.
    pixel_um : float
        Object pixel of that grid, µm.
    oversample : int
        Frequency oversampling of the sub-aperture integrals (1: the image grid's own steps).

    Attributes
    ----------
    i0 : ndarray, float, (K,)
        Each lenslet's direct-light background (fraction of the condenser light).
    m_out : (int, int)
        Band grid size (my, mx), unshifted FFT order.
    """

    def __init__(self, optics: Optics, lenslets, shape, pixel_um, oversample=1):
        self.lenslets = list(lenslets)
        if not self.lenslets:
            raise SsdpcError("no lenslets; calibrate the lattice first")
        self.shape = tuple(int(n) for n in shape)
        self.r = r = int(oversample)
        if r < 1:
            raise SsdpcError(f"oversample must be >= 1, got {oversample}")
        coarse = _frequency_steps(self.shape, pixel_um)
        self.du = du = tuple(d / r for d in coarse)
        rho = float(Pupil.of(optics).lenslet_arrays(self.lenslets)[1].max())  # the widest sub-aperture
        m_in = tuple(2 * int(math.ceil(rho / d)) + 4 for d in du)
        self.m_out = tuple(min(n, 2 * int(math.ceil(2 * rho / d)) + 3) for n, d in zip(self.shape, coarse))
        src, pup, eta = [], [], []
        for ln in self.lenslets:
            p, ux, uy = subaperture_pupil(optics, ln, m_in, du)  # P_k with the optics' aberrations
            cx, cy = optics.source_centre  # the condenser disk, off axis where the aberrations say so
            src.append(soft_disk(np.hypot(ux - cx, uy - cy), optics.source_radius, math.sqrt(du[0] * du[1])))
            pup.append(p)
            eta.append(axial_frequency(ux, uy, optics))
        self.src, self.pup, self.eta = np.stack(src), np.stack(pup), np.stack(eta)
        self.norm = _disk_power(optics.source_radius, du)
        self.i0 = _binary_background(self.src, self.pup, self.norm)

    def band(self, zs):
        """(H_abs, H_phase) (Z, K, my, mx) on the band grid for the depths ``zs`` (1D).

        Parameters
        ----------
        zs : ndarray, (Z,)
            Depths, µm.

        Returns
        -------
        h_abs, h_phase : ndarray, complex64, (Z, K, my, mx)
            Absorption and phase transfer functions (paper Eqs. 2-4), unshifted FFT order.
        """
        r, m_out = self.r, self.m_out
        fine = tuple(m * r for m in m_out)
        h_abs, h_phase = weak_object_transfer_functions(self.src, self.pup, zs, self.eta, fine, self.norm)
        if r > 1:  # the fine samples at multiples of r are the output grid
            iy, ix = ((fft_indices(m) * r) % f for m, f in zip(m_out, fine))
            h_abs, h_phase = (h[..., iy[:, None], ix[None, :]] for h in (h_abs, h_phase))
        h_abs[..., 0, 0] = 2 * self.i0
        return h_abs, h_phase

    def embed(self, h):
        """Band grid -> output grid (zeros beyond 2ρ, where the WOTF vanishes).

        Parameters
        ----------
        h : ndarray, (..., my, mx)
            Transfer functions on the band grid.

        Returns
        -------
        ndarray, complex64, (..., ny, nx)
            On the image grid, unshifted FFT order.
        """
        return h if h.shape[-2:] == self.shape else zero_padded(h, self.shape)


def _binary_background(src, pupil, norm):
    """I0 = ∫ S |P|² / ∫ S for a 0/1 pupil whose edge samples hold area fractions a: the cell
    average of |P|² is a, not a² (a² would lose ~du/(3ρ), 1.6% for a paper sub-aperture)."""
    return np.sum(src * np.abs(pupil), axis=(-2, -1)) / norm


def _disk_power(radius, du):
    """Power of a uniform disk source in grid samples (its area / du²)."""
    return math.pi * radius**2 / (du[0] * du[1])


def paper_transfer_functions(optics: Optics, shape, pixel_um, z_um=0.0):
    """Transfer functions of paper Eq. 4: half of the condenser disk as the source, full pupil.

    Parameters
    ----------
    optics : Optics
    shape : (int, int)
        Output grid (ny, nx).
    pixel_um : float
        Object pixel, µm.
    z_um : float or sequence of float
        Defocus, µm.

    Returns
    -------
    dict
        {half: (H_abs, H_phase, I0)} for 'up', 'down', 'left', 'right'.
    """
    du = _frequency_steps(shape, pixel_um)
    r = optics.cutoff
    m_in = tuple(2 * int(math.ceil(r / d)) + 4 for d in du)
    fy = (fft_indices(m_in[0]) * du[0])[:, None]
    fx = (fft_indices(m_in[1]) * du[1])[None, :]
    step = math.sqrt(du[0] * du[1])
    cx, cy = optics.source_centre
    disk = soft_disk(np.hypot(fx - cx, fy - cy), optics.source_radius, step)
    full = Pupil.of(optics)
    pupil = full.objective(fx, fy, step) * np.exp(1j * full.phase(fx, fy))  # the objective's aberration
    eta = axial_frequency(fx, fy, optics)
    norm = _disk_power(optics.source_radius, du)
    # "up" sees u_y > 0 (docs/conventions.md); the half-plane edge gets half weight
    sides = {"up": fy / du[0], "down": -fy / du[0], "left": fx / du[1], "right": -fx / du[1]}
    out = {}
    for half, coord in sides.items():
        src = disk * np.clip(0.5 + coord, 0.0, 1.0)
        h_abs, h_phase = weak_object_transfer_functions(src, pupil, z_um, eta, shape, norm)
        i0 = float(_binary_background(src, pupil, norm))
        h_abs[..., 0, 0] = 2 * i0
        out[half] = (h_abs, h_phase, i0)
    return out
