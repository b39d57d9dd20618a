"""Robust statistics every layer uses: one definition of a robust standard deviation."""

from __future__ import annotations

import numpy as np

__all__ = ["MAD_TO_SIGMA", "robust_sigma"]

#: σ of a normal distribution per median absolute deviation: 1 / Φ⁻¹(3/4).
MAD_TO_SIGMA = 1.4826


def robust_sigma(values, about: float | None = None) -> float:
    """A robust standard deviation: 1.4826 x the median absolute deviation.

    Parameters
    ----------
    values : array_like
        Samples (any shape; flattened).
    about : float, optional
        The centre the deviations are taken from; None: the samples' median (the MAD). Give 0
        for residuals, whose centre is known.

    Returns
    -------
    float
        σ in the samples' units; 0 for no spread; NaN for no samples.
    """
    a = np.asarray(values, dtype=np.float64).ravel()
    if a.size == 0:
        return float("nan")
    centre = float(np.median(a)) if about is None else float(about)
    return MAD_TO_SIGMA * float(np.median(np.abs(a - centre)))
