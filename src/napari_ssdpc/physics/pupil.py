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

    P_obj(u) = circ(|u| ≤ NA/λ) and A_k(u) = P_obj(u)·circ(|u − u_k| ≤ ρ_k) (paper Eqs. 2 and 6;
    docs/conventions.md for u_k), and the complex pupil of view k

        P_k(u) = A_k(u) exp(i2π [W(u) + d_k |u − u_k|² / ρ_k²])

    with W the objective's wavefront (Zernike terms over |u| ≤ NA/λ, waves) and d_k the lenslet's
    defocus (waves at its sub-aperture's edge); u_k and ρ_k are the lenslet's own centre and radius
    (docs/aberrations.md). The nominal optics give the ideal pupil; a positive defocus term has the
    sign of a point nearer the objective (z < 0: exp(i2π z η) falls with |u| where it rises).

    Attributes
    ----------
    cutoff : float
        NA/λ, the objective's cut-off, cycles/µm.
    rho : float
        ρ, the nominal sub-aperture radius, cycles/µm.
    zernike : tuple of float
        The objective's Noll coefficients from j = 1, waves.
    lenslet_terms : tuple
        ((row, col), (du_x, du_y), radius_scale, defocus_waves) of the lenslets that differ: the
        centre's shift in cycles/µm.
    """

    cutoff: float
    rho: float
    zernike: tuple[float, ...] = ()
    lenslet_terms: tuple = ()

    @classmethod
    def of(cls, optics: Optics) -> Pupil:
        """The pupil of the optics, with what its ``aberrations`` add.

        Parameters
        ----------
        optics : Optics
            Its NA, wavelength, sub-aperture radius and aberrations.

        Returns
        -------
        Pupil
            Ideal where the aberrations are all zero (the default).
        """
        from napari_ssdpc.physics.geometry import mla_to_frequency

        ab = optics.aberrations
        terms = tuple(
            ((t.row, t.col), _pair(mla_to_frequency(optics, t.offset_um)), t.radius_scale, t.defocus_waves)
            for t in ab.lenslets
            if not t.is_nominal
        )
        zernike = tuple(float(c) for c in ab.objective_zernike_waves) if any(ab.objective_zernike_waves) else ()
        return cls(float(optics.cutoff), float(optics.subaperture_radius), zernike, terms)

    @property
    def rho_max(self) -> float:
        """The widest sub-aperture's radius, cycles/µm (ρ for the nominal array)."""
        return self.rho * max([1.0, *(scale for _, _, scale, _ in self.lenslet_terms)])

    @property
    def aberrated(self) -> bool:
        """Whether the pupil has a phase or a lenslet off its nominal sub-aperture."""
        return bool(self.zernike or self.lenslet_terms)

    def lenslet(self, lenslet) -> tuple[tuple[float, float], float, float]:
        """(u_k, ρ_k, d_k) of a lenslet: its sub-aperture's centre (cycles/µm), radius (cycles/µm)
        and defocus (waves at the edge).

        Parameters
        ----------
        lenslet : Lenslet or array_like (2,)
            A lenslet of the array, or a bare centre u_k (nominal terms).

        Returns
        -------
        tuple
        """
        if not hasattr(lenslet, "row"):
            return (float(lenslet[0]), float(lenslet[1])), self.rho, 0.0
        u = (float(lenslet.u[0]), float(lenslet.u[1]))
        for key, shift, scale, defocus in self.lenslet_terms:
            if key == (lenslet.row, lenslet.col):
                return (u[0] + shift[0], u[1] + shift[1]), self.rho * scale, defocus
        return u, self.rho, 0.0

    def area_fraction(self, lenslet) -> float:
        """The area of A_k (the lenslet's own sub-aperture inside the objective's pupil) over the
        nominal sub-aperture's, π ρ²: the lenslet's ``fraction`` for the nominal optics.

        Parameters
        ----------
        lenslet : Lenslet or array_like (2,)

        Returns
        -------
        float
        """
        from napari_ssdpc.settings.lenslets import circle_overlap_fraction

        u_k, rho, _ = self.lenslet(lenslet)
        return float(circle_overlap_fraction(math.hypot(*u_k), rho, self.cutoff)) * (rho / self.rho) ** 2

    def lenslet_arrays(self, lenslets) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`lenslet` of many: u_k (K, 2), ρ_k (K,), d_k (K,).

        Parameters
        ----------
        lenslets : list of Lenslet, or ndarray (K, 2) of bare centres
        """
        rows = [self.lenslet(ln) for ln in lenslets]
        return (
            np.array([r[0] for r in rows], float).reshape(-1, 2),
            np.array([r[1] for r in rows], float),
            np.array([r[2] for r in rows], float),
        )

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

    def subaperture(self, ux, uy, u_k, step: float | None = None, xp=np, rho=None):
        """A_k = P_obj · circ(|u − u_k| ≤ ρ_k) at (ux, uy) (hard-edged, or ramped with ``step``).

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
        rho : float or ndarray, optional
            The sub-aperture's radius, cycles/µm (broadcastable); default the nominal ρ.

        Returns
        -------
        ndarray, bool, or float in [0, 1] with ``step``
        """
        rho = self.rho if rho is None else rho
        dx, dy = ux - u_k[0], uy - u_k[1]
        if step is None:
            return (dx * dx + dy * dy <= rho * rho) & self.objective(ux, uy)
        return soft_disk(xp.hypot(dx, dy), rho, step) * self.objective(ux, uy, step, xp)

    def phase(self, ux, uy, u_k=None, rho=None, defocus=None, xp=np, objective: bool = True):
        """2π [W(u) + d_k |u − u_k|² / ρ_k²], the pupil's phase, rad (0 for the nominal optics).

        Parameters
        ----------
        ux, uy : ndarray
            Frequencies, cycles/µm (broadcastable).
        u_k : array_like, optional
            The sub-aperture's centre, cycles/µm (needed with ``defocus``).
        rho : float or ndarray, optional
            Its radius, cycles/µm; default the nominal ρ.
        defocus : float or ndarray, optional
            d_k, waves at the sub-aperture's edge (broadcastable); None: none.
        xp : module
            NumPy or CuPy.
        objective : bool
            Include the objective's term (False: the lenslet's alone, for a model that applies the
            objective's phase before the field stop).

        Returns
        -------
        ndarray, float
            Broadcast shape of the inputs (the objective's term is 0 beyond its cut-off).
        """
        from napari_ssdpc.physics.zernike import zernike_sum

        waves = 0.0 * ux + 0.0 * uy
        if self.zernike and objective:
            r = xp.hypot(ux, uy) / self.cutoff
            waves = waves + xp.where(r <= 1.0, zernike_sum(self.zernike, xp.minimum(r, 1.0), xp.arctan2(uy, ux)), 0.0)
        if defocus is not None:
            rho = self.rho if rho is None else rho
            waves = waves + defocus * ((ux - u_k[0]) ** 2 + (uy - u_k[1]) ** 2) / (rho * rho)
        return (2 * math.pi) * waves

    def field(self, ux, uy, lenslet, step: float | None = None, xp=np, objective: bool = True):
        """P_k(u) = A_k(u) exp(i phase) of one lenslet: real (A_k) for the nominal optics.

        Parameters
        ----------
        ux, uy : ndarray
            Frequencies, cycles/µm (broadcastable).
        lenslet : Lenslet or array_like (2,)
            The lenslet (its own terms), or a bare centre u_k.
        step : float, optional
            The sampling step, cycles/µm (a ramped edge).
        xp : module
            NumPy or CuPy.
        objective : bool
            Include the objective's phase (False: the path behind the field stop, lenslet alone).

        Returns
        -------
        ndarray
            Complex where the pupil is aberrated, else as :meth:`subaperture`.
        """
        u_k, rho, defocus = self.lenslet(lenslet)
        amplitude = self.subaperture(ux, uy, u_k, step, xp, rho)
        if not (defocus or (objective and self.zernike)):
            return amplitude
        return amplitude * xp.exp(1j * self.phase(ux, uy, u_k, rho, defocus or None, xp, objective))

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


def _pair(v) -> tuple[float, float]:
    return float(v[0]), float(v[1])


def subaperture_pupil(optics: Optics, lenslet, shape, du):
    """P_k(u) of a lenslet (:meth:`Pupil.field`) on the grid u = u_k + fftfreq (unshifted FFT order).

    The lenslet's sub-aperture of the objective pupil (paper Eq. 2) with the optics' aberrations,
    sampled around its own centre u_k.

    Parameters
    ----------
    optics : Optics
    lenslet : Lenslet or array_like, shape (2,)
        The lenslet, or a bare sub-aperture centre (x, y), cycles/µm (nominal terms).
    shape : tuple of int
        (ny, nx) samples.
    du : float or array_like, shape (2,)
        Frequency step, cycles/µm: one for both axes or (du_y, du_x).

    Returns
    -------
    P : ndarray, shape (ny, nx)
        The pupil: its amplitude in [0, 1], real for the nominal optics, complex where aberrated.
    ux, uy : ndarray
        The absolute frequencies, cycles/µm, broadcastable to ``shape``.
    """
    ny, nx = shape
    d = np.broadcast_to(np.asarray(du, dtype=float), (2,))  # a scalar step or (du_y, du_x)
    duy, dux = float(d[0]), float(d[1])
    pupil = Pupil.of(optics)
    u_k = pupil.lenslet(lenslet)[0]
    fy = sfft.fftfreq(ny, 1.0 / (ny * duy))[:, None]
    fx = sfft.fftfreq(nx, 1.0 / (nx * dux))[None, :]
    ux, uy = u_k[0] + fx, u_k[1] + fy
    return pupil.field(ux, uy, lenslet, step=math.sqrt(dux * duy)), ux, uy


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
