"""Scalar wave optics on a periodic frequency lattice: the pieces a wave model of the instrument shares.

- Angular-spectrum propagation in a homogeneous medium (paper Eq. 6, the free-space propagation
  between the planes of the multislice and from the sample to the focal plane): a plane wave
  exp(i2π(u·x + η z)) with η(u) = sqrt((n/λ)² − |u|²) (:func:`napari_ssdpc.physics.pupil.eta`)
  gains exp(i2π d η(u)) over a distance d toward the objective, so a field's spectrum is
  multiplied by the transfer function H_d(u) = exp(i2π d η(u)). Evanescent components
  (|u| > n/λ, η imaginary) decay over |d| in either direction, or are cut.
- The apertures and the Köhler source on the same lattice are in :mod:`napari_ssdpc.physics.apertures`.

Frequencies are in cycles/µm, distances in µm; lattice arrays are in FFT order unless said.
"""

from __future__ import annotations

import numpy as np

from napari_ssdpc.backend import cpu
from napari_ssdpc.physics.pupil import eta

__all__ = ["apply_transfer", "defocus_factor", "propagate", "propagator", "transfer_function"]


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
    return cpu().ifft2(cpu().fft2(field) * h)


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
