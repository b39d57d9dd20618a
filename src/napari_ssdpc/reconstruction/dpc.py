"""DPC images (paper Eq. 1), Tikhonov phase (Eq. 7) and RI conversion (Δn = λφ/(2π d)).

Arrays may carry leading axes (e.g. z): the 2D FFTs act on the last two axes.
"""

from __future__ import annotations

import numpy as np

from napari_ssdpc.backend import cpu


def dpc_image(i1, i2, eps: float = 1e-6, background=None):
    """(I₁ − I₂)/(I₁ + I₂), paper Eq. 1.

    ``background`` replaces the denominator when given (e.g. the z-summed background of
    a deconvolved stack, so that every slice is normalised by the same total intensity).

    Parameters
    ----------
    i1, i2 : ndarray
        The two halves' images (same shape).
    eps : float
        Floor of the denominator.
    background : ndarray, optional
        Replaces I₁ + I₂.

    Returns
    -------
    ndarray, float32
    """
    i1 = np.asarray(i1, dtype=np.float32)
    i2 = np.asarray(i2, dtype=np.float32)
    den = (i1 + i2) if background is None else np.asarray(background, dtype=np.float32)
    return (i1 - i2) / np.maximum(den, eps)


def tikhonov_phase(dpc, h_phase, alpha: float):
    """Least-squares phase from DPC images with Tikhonov regularisation, paper Eq. 7.

    ``dpc``: sequence of DPC images (..., ny, nx), one per axis j.
    ``h_phase``: matching DPC phase transfer functions (ny, nx) or (..., ny, nx) in
    unshifted FFT order, so that F[dpc_j] = h_phase_j · F[φ].
    φ = F⁻¹{ Σ_j H_j* F[dpc_j] / (Σ_j |H_j|² + α) }.

    Parameters
    ----------
    dpc : sequence of ndarray, (..., ny, nx)
    h_phase : sequence of ndarray, complex
    alpha : float
        Regularisation α (paper Eq. 7).

    Returns
    -------
    ndarray, float32, (..., ny, nx)
        Phase, rad.
    """
    num = 0
    den = alpha
    for img, h in zip(dpc, h_phase):
        num = num + np.conj(h) * cpu().fft2(img)
        den = den + np.abs(h) ** 2
    return cpu().ifft2(num / den).real.astype(np.float32)


def phase_to_delta_n(phase, wavelength_um: float, dz_um: float):
    """Δn = λ φ / (2π d) with the vacuum wavelength and the slice spacing d.

    Parameters
    ----------
    phase : ndarray
        Phase per slab, rad.
    wavelength_um : float
        Vacuum wavelength, µm.
    dz_um : float
        Slab thickness, µm.

    Returns
    -------
    ndarray
        Δn (no unit).
    """
    return np.asarray(phase, dtype=np.float32) * np.float32(wavelength_um / (2 * np.pi * dz_um))
