"""Pupils and propagation in the frequency domain: the pieces every model of the instrument uses.

- η(u) = sqrt((n/λ)² − |u|²), the axial spatial frequency in the medium (a plane wave
  exp(i2π(u·x + η z)) propagates toward +z, docs/conventions.md);
- the anti-aliased disk of the pupils and the source;
- the sub-aperture pupil of lenslet k, P_k(u) = P_obj(u)·circ(|u − u_k| ≤ ρ) (paper Eq. 6);
- the parallax vector t_k = <u/η(u)>_{|P_k|²}: a point at depth z appears displaced by z·t_k in the
  EI of lenslet k (the |P_k|²-weighted mean tanθ·û).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.optics import Optics

__all__ = ["axial_frequency", "eta", "mean_tilt", "soft_disk", "subaperture_pupil"]


def soft_disk(dist, radius, step):
    """Disk sampled with an antialiased edge: a linear ramp one sample wide, so that the sampled
    amplitude integrates to the disk area to second order in the step.

    Parameters
    ----------
    dist : array_like
        Distance of each sample from the disk's centre (any unit).
    radius : float
        The disk's radius, same unit.
    step : float
        The sampling step, same unit.

    Returns
    -------
    ndarray
        Values in [0, 1], shaped like ``dist``.
    """
    return np.clip(0.5 + (radius - np.asarray(dist)) / step, 0.0, 1.0)


def eta(u2, n_medium: float, wavelength_um: float) -> np.ndarray:
    """η(u) = sqrt((n/λ)² − |u|²) (cycles/µm) for |u|² = ``u2``, imaginary (evanescent) beyond n/λ.

    Parameters
    ----------
    u2 : array_like
        Squared lateral spatial frequency |u|², (cycles/µm)².
    n_medium : float
        Refractive index of the medium.
    wavelength_um : float
        Vacuum wavelength, µm.

    Returns
    -------
    ndarray, complex128
        The axial spatial frequency; a plane wave exp(i2π(u·x + η z)) propagates toward +z.
    """
    return np.sqrt(((n_medium / wavelength_um) ** 2 - np.asarray(u2, dtype=np.float64)).astype(np.complex128))


def axial_frequency(ux, uy, optics: Optics) -> np.ndarray:
    """Real part of :func:`eta` at (ux, uy) for the optics' medium: 0 for evanescent waves.

    Parameters
    ----------
    ux, uy : array_like
        Lateral spatial frequencies, cycles/µm (broadcastable).
    optics : Optics

    Returns
    -------
    ndarray, float64
        η(u) in cycles/µm.
    """
    return eta(np.asarray(ux) ** 2 + np.asarray(uy) ** 2, optics.medium_index, optics.wavelength_um).real


def subaperture_pupil(optics: Optics, u_k, shape, du):
    """P_k = P_obj·circ(|u − u_k| ≤ ρ) on the grid u = u_k + fftfreq (unshifted FFT order).

    The lenslet's sub-aperture of the objective pupil (paper Eq. 2), sampled around its centre.

    Parameters
    ----------
    optics : Optics
    u_k : array_like, shape (2,)
        The sub-aperture's centre (x, y), cycles/µm.
    shape : tuple of int
        (ny, nx) samples.
    du : float or array_like, shape (2,)
        Frequency step, cycles/µm: one for both axes or (du_y, du_x).

    Returns
    -------
    P : ndarray, shape (ny, nx)
        The pupil amplitude in [0, 1].
    ux, uy : ndarray
        The absolute frequencies, cycles/µm, broadcastable to ``shape``.
    """
    ny, nx = shape
    d = np.broadcast_to(np.asarray(du, dtype=float), (2,))  # a scalar step or (du_y, du_x)
    duy, dux = float(d[0]), float(d[1])
    fy = sfft.fftfreq(ny, 1.0 / (ny * duy))[:, None]
    fx = sfft.fftfreq(nx, 1.0 / (nx * dux))[None, :]
    ux, uy = u_k[0] + fx, u_k[1] + fy
    step = math.sqrt(dux * duy)
    p = soft_disk(np.hypot(fx, fy), optics.subaperture_radius, step)
    p = p * soft_disk(np.hypot(ux, uy), optics.cutoff, step)
    return p, ux, uy


def mean_tilt(optics: Optics, pupil, ux, uy) -> np.ndarray:
    """<u/η(u)> weighted by |P|²: a point at depth z appears displaced by z times this (parallax).

    Parameters
    ----------
    optics : Optics
    pupil : ndarray
        The sub-aperture pupil amplitude (from :func:`subaperture_pupil`).
    ux, uy : ndarray
        Its absolute frequencies, cycles/µm.

    Returns
    -------
    ndarray, shape (2,)
        tan θ (x, y), dimensionless: µm of lateral shift per µm of depth.
    """
    w = np.abs(pupil) ** 2
    eta = axial_frequency(ux, uy, optics)
    total = w.sum()
    if total <= 0:
        raise SsdpcError("a lenslet sub-aperture lies outside the objective pupil; drop it from the lenslet list")
    return np.array([np.sum(w * ux / eta), np.sum(w * uy / eta)]) / total
