"""Zernike polynomials in Noll's order and normalisation: the objective's aberration over its pupil.

Noll's index j = 1, 2, 3, ... orders the polynomials Z_j(r, θ) on the unit disk by radial order n
and azimuthal order m (j = 1 piston, 2 and 3 tilt, 4 defocus, 5 and 6 astigmatism, 7 and 8 coma,
11 primary spherical). Each is normalised to unit root-mean-square over the disk:

    Z_j = sqrt(n + 1) R_n^0(r)                 m = 0
    Z_j = sqrt(2 (n + 1)) R_n^|m|(r) cos(m θ)   m > 0 (even j)
    Z_j = sqrt(2 (n + 1)) R_n^|m|(r) sin(|m| θ) m < 0 (odd j)

so a coefficient is the wavefront's rms over the pupil (docs/aberrations.md). On the pupil r = |u| /
(NA/λ) and θ = atan2(u_y, u_x), with x to the right and y down as everywhere in the package.
"""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.errors import SsdpcError

__all__ = ["noll_to_nm", "zernike", "zernike_sum"]


def noll_to_nm(j: int) -> tuple[int, int]:
    """Radial and azimuthal order (n, m) of Noll's index j.

    Parameters
    ----------
    j : int
        Noll index, 1 or more.

    Returns
    -------
    (int, int)
        n >= 0 and m with |m| <= n, n − |m| even; m < 0 for the sine terms (odd j).
    """
    if int(j) != j or j < 1:
        raise SsdpcError(f"a Noll index is a whole number from 1 (piston), got {j}")
    n, rest = 0, int(j) - 1
    while rest > n:
        n += 1
        rest -= n
    m_abs = (n % 2) + 2 * ((rest + (n + 1) % 2) // 2)
    return n, (m_abs if j % 2 == 0 else -m_abs)


def _radial(n: int, m_abs: int, r):
    """R_n^|m|(r), the radial polynomial."""
    out = np.zeros_like(r)
    for s in range((n - m_abs) // 2 + 1):
        c = (-1) ** s * math.factorial(n - s)
        c /= math.factorial(s) * math.factorial((n + m_abs) // 2 - s) * math.factorial((n - m_abs) // 2 - s)
        out = out + c * r ** (n - 2 * s)
    return out


def zernike(j: int, r, theta):
    """Z_j(r, θ), rms-normalised over the unit disk (0 outside it is the caller's choice).

    Parameters
    ----------
    j : int
        Noll index.
    r, theta : ndarray
        Radius (unit disk) and angle, rad; NumPy or CuPy, broadcastable.

    Returns
    -------
    ndarray
        Shaped as the broadcast of ``r`` and ``theta``.
    """
    n, m = noll_to_nm(j)
    radial = _radial(n, abs(m), r)
    if m == 0:
        return math.sqrt(n + 1) * radial + 0 * theta
    trig = np.cos(m * theta) if m > 0 else np.sin(-m * theta)
    return math.sqrt(2 * (n + 1)) * radial * trig


def zernike_sum(coefficients, r, theta):
    """Σ_j c_j Z_j(r, θ) for j = 1, 2, ... (``coefficients[0]`` is piston).

    Parameters
    ----------
    coefficients : sequence of float
        Noll coefficients from j = 1, any unit (waves for a wavefront).
    r, theta : ndarray
        Unit-disk radius and angle, rad, broadcastable.

    Returns
    -------
    ndarray
        The sum, in the coefficients' unit; zeros where every coefficient is 0.
    """
    total = 0 * r + 0 * theta
    for j, c in enumerate(coefficients, start=1):
        if c:
            total = total + float(c) * zernike(j, r, theta)
    return total
