"""Elementwise proximal steps and constraints of the phase solvers: the box of the sign and bound
constraints, the prox of the sparsity with the temporal prior, and the two over-relaxed ADMM
steps of ``tv`` that use them (:mod:`.regularised`; the box also in :mod:`.methods.multislice`)."""

from __future__ import annotations

import numpy as np

__all__ = ["RELAX", "bounds", "constraint_step", "gradient_step", "prox_two_kinks"]

#: Over-relaxation of the ADMM splits (1: none; 1.5-1.8 is usual).
RELAX = 1.6


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


def constraint_step(phi, z2, u2, l1, box, scratch, mask, parts, xp=np, prior=None, gamma=0.0) -> None:
    """Over-relaxed ADMM step of the constraint split, in place: v = αφ + (1 − α)z₂ + u₂,
    z₂ = P_C(prox(v)) (the sparsity prox, with a ``prior`` the prox of the sparsity and the
    temporal prior :func:`prox_two_kinks`, then the sign, bound and field stop) and u₂ = v − z₂.

    Parameters
    ----------
    phi, z2, u2 : ndarray, float32, (Z, ny, nx)
        The phase, the split and its scaled multiplier (rad); ``z2`` and ``u2`` are updated.
    l1 : float
        The sparsity threshold μ (rad).
    box : (float, float)
        Lower and upper bound of the phase (:func:`bounds`), rad.
    scratch : ndarray, float32, (Z, ny, nx)
        Work array, overwritten.
    mask : ndarray, (ny, nx)
        The field stop (1 inside).
    parts : callable
        ``parts(part)``: runs ``part(slice_of_planes)`` over the planes and sums what it returns.
    xp : module
        NumPy or CuPy.
    prior : ndarray, (Z, ny, nx), optional
        The previous frame's phase (temporal prior), rad.
    gamma : float
        The temporal prior's threshold γ (rad).
    """

    def part(sl):
        z, u, s = z2[sl], u2[sl], scratch[sl]
        z *= np.float32(1 - RELAX)
        u += z
        xp.multiply(phi[sl], np.float32(RELAX), out=s)
        u += s  # u holds v
        if prior is None:
            xp.clip(u, -l1, l1, out=z)
            xp.subtract(u, z, out=z)  # shrink(v, μ)
        else:
            z[...] = prox_two_kinks(u, prior[sl], l1, gamma, xp)
        xp.clip(z, *box, out=z)
        z *= mask
        u -= z
        return 0.0

    parts(part)


def gradient_step(g, z1, u1, thresh, parts, xp=np) -> float:
    """Over-relaxed ADMM step of the gradient split (Boyd et al. 2011, §3.4.3), in place:
    v = αDφ + (1 − α)z₁ + u₁, z₁ = shrink(v, t) and u₁ = v − z₁ = clip(v, ±t).

    Parameters
    ----------
    g : ndarray, float32, (D, Z, ny, nx)
        Dφ (its D finite-difference components) on entry; overwritten.
    z1, u1 : ndarray, float32, (D, Z, ny, nx)
        The split and its scaled multiplier; updated.
    thresh : float
        The shrinkage threshold t.
    parts, xp
        As for :func:`constraint_step`.

    Returns
    -------
    float
        Σ|Dφ|.
    """

    def part(sl):
        gp, zp, up = g[:, sl], z1[:, sl], u1[:, sl]
        tv = float(abs(gp).sum())
        gp *= np.float32(RELAX)
        zp *= np.float32(1 - RELAX)
        gp += zp
        gp += up
        xp.clip(gp, -thresh, thresh, out=up)
        xp.subtract(gp, up, out=zp)
        return tv

    return parts(part)
