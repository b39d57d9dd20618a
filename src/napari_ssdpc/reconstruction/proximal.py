"""Elementwise proximal steps and constraints of the phase solvers: the box of the sign and bound
constraints, and the prox of the sparsity with the temporal prior (:mod:`.regularised`; the box
also in :mod:`.methods.multislice`)."""

from __future__ import annotations

import numpy as np

__all__ = ["bounds", "prox_two_kinks"]


def prox_two_kinks(v, p, mu, gamma, xp=np):
    """argmin_z μ|z| + γ|z − p| + ½(z − v)², elementwise: the sparsity and the temporal prior.

    The sum of two absolute values has its kinks at lo = min(0, p) and hi = max(0, p), with the
    weights w_lo and w_hi of the terms that sit there; the minimiser is v + w_lo + w_hi where that
    lies below lo, v − w_lo − w_hi where that lies above hi, and else v − w_lo + w_hi clipped to
    [lo, hi]. With p = 0 it is the shrinkage by μ + γ. A box constraint (the sign and the bound)
    is then a clip: the function is convex in one variable.

    Parameters
    ----------
    v, p : array, float32, same shape
        The point and the prior (the previous frame's phase), rad.
    mu, gamma : float
        The weights of |z| and |z − p| (≥ 0), in the units of v.
    xp : module
        NumPy or CuPy.

    Returns
    -------
    array, float32, shaped like v
    """
    mu, gamma = np.float32(mu), np.float32(gamma)
    lo, hi = xp.minimum(p, 0), xp.maximum(p, 0)
    # p ≥ 0: |z| kinks at lo = 0 (w_lo = μ), |z − p| at hi (w_hi = γ); p < 0: the other way round
    inner = xp.where(p >= 0, v - mu + gamma, v - gamma + mu)
    z = xp.clip(inner, lo, hi)
    total = mu + gamma
    below, above = v + total, v - total
    z = xp.where(below < lo, below, z)
    return xp.where(above > hi, above, z).astype(np.float32, copy=False)


def bounds(sign, phi_max) -> tuple[float, float]:
    """(lo, hi) of φ for a sign constraint and a bound |φ| ≤ φ_max (any unit: Δn too).

    Parameters
    ----------
    sign : {'denser', 'lighter', 'any'}
    phi_max : float

    Returns
    -------
    tuple of float
    """
    return (0.0 if sign == "denser" else -phi_max, 0.0 if sign == "lighter" else phi_max)
