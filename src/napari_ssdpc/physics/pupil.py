"""Pupils and propagation in the frequency domain: the pieces every model of the instrument uses.

- η(u) = sqrt((n/λ)² − |u|²), the axial spatial frequency in the medium (a plane wave
  exp(i2π(u·x + η z)) propagates toward +z, docs/conventions.md);
- the anti-aliased disk of the pupils and the source;
- :class:`Pupil`, the one definition of the detection pupil: the objective's P_obj(u) = circ(|u| ≤ NA/λ)
  and the sub-aperture of lenslet k, A_k(u) = P_obj(u)·circ(|u − u_k| ≤ ρ) (paper Eqs. 2 and 6),
  which the transfer functions, the PSF, the multislice model and the simulator all sample (with
  hard edges, a one-sample edge ramp, or the area fraction of a lattice cell);
- the sub-aperture pupil of lenslet k on a grid around u_k (:func:`subaperture_pupil`);
- the parallax vector t_k = <u/η(u)>_{|P_k|²}: a point at depth z appears displaced by z·t_k in the
  EI of lenslet k (the |P_k|²-weighted mean tanθ·û).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.optics import Optics

__all__ = ["Pupil", "axial_frequency", "eta", "mean_tilt", "soft_disk", "subaperture_pupil"]


def soft_disk(dist, radius, step):
    """Disk sampled with an antialiased edge: a linear ramp one sample wide, so that the sampled
    amplitude integrates to the disk area to second order in the step.

    Parameters
    ----------
    dist : array_like
        Distance of each sample from the disk's centre (any unit); NumPy or CuPy.
    radius : float
        The disk's radius, same unit.
    step : float
        The sampling step, same unit.

    Returns
    -------
    ndarray
        Values in [0, 1], shaped like ``dist``.
    """
    d = dist if hasattr(dist, "clip") else np.asarray(dist)  # NumPy or CuPy arrays as they are
    return (0.5 + (radius - d) / step).clip(0.0, 1.0)


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


@dataclass(frozen=True)
class Pupil:
    """The detection pupil of every view: the objective's pupil cut by each lenslet's sub-aperture.

    P_obj(u) = circ(|u| ≤ NA/λ) and A_k(u) = P_obj(u)·circ(|u − u_k| ≤ ρ) (paper Eqs. 2 and 6;
    docs/conventions.md for u_k). The nominal optics give the ideal pupil (:meth:`of`); what a real
    instrument adds (a phase over P_obj, each lenslet's own centre and radius) belongs here, so that
    every model that samples the pupil sees it.

    Attributes
    ----------
    cutoff : float
        NA/λ, the objective's cut-off, cycles/µm.
    rho : float
        ρ, a lenslet's sub-aperture radius, cycles/µm.
    """

    cutoff: float
    rho: float

    @classmethod
    def of(cls, optics: Optics) -> Pupil:
        """The pupil of the nominal optics.

        Parameters
        ----------
        optics : Optics
            Its NA, wavelength and sub-aperture radius.

        Returns
        -------
        Pupil
            Ideal: no aberration, every lenslet at its nominal place.
        """
        return cls(float(optics.cutoff), float(optics.subaperture_radius))

    def objective(self, ux, uy, step: float | None = None, xp=np):
        """P_obj at (ux, uy): hard-edged (bool), or with ``step`` its edge a linear ramp one sample wide.

        Parameters
        ----------
        ux, uy : ndarray
            Frequencies, cycles/µm (broadcastable).
        step : float, optional
            The sampling step, cycles/µm (:func:`soft_disk`).
        xp : module
            NumPy or CuPy.

        Returns
        -------
        ndarray, bool, or float in [0, 1] with ``step``
        """
        if step is None:
            return ux * ux + uy * uy <= self.cutoff * self.cutoff
        return soft_disk(xp.hypot(ux, uy), self.cutoff, step)

    def subaperture(self, ux, uy, u_k, step: float | None = None, xp=np):
        """A_k = P_obj · circ(|u − u_k| ≤ ρ) at (ux, uy) (hard-edged, or ramped with ``step``).

        Parameters
        ----------
        ux, uy : ndarray
            Frequencies, cycles/µm (broadcastable).
        u_k : array_like, (2,) or broadcastable pair
            The sub-aperture's centre (x, y), cycles/µm.
        step : float, optional
            The sampling step, cycles/µm.
        xp : module
            NumPy or CuPy.

        Returns
        -------
        ndarray, bool, or float in [0, 1] with ``step``
        """
        dx, dy = ux - u_k[0], uy - u_k[1]
        if step is None:
            return (dx * dx + dy * dy <= self.rho * self.rho) & self.objective(ux, uy)
        return soft_disk(xp.hypot(dx, dy), self.rho, step) * self.objective(ux, uy, step, xp)

    def objective_cells(self, u2, du: float) -> np.ndarray:
        """P_obj on a lattice of step ``du``: every cell that touches |u| ≤ NA/λ passes (its exact,
        area-weighted edge is applied by the sub-apertures).

        Parameters
        ----------
        u2 : ndarray
            |u|² of the lattice, (cycles/µm)².
        du : float
            Lattice step, cycles/µm.

        Returns
        -------
        ndarray, float32, shape of ``u2``
            1 or 0.
        """
        return (u2 <= (self.cutoff + du / math.sqrt(2)) ** 2).astype(np.float32)


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
    return Pupil.of(optics).subaperture(ux, uy, u_k, step=math.sqrt(dux * duy)), ux, uy


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
