"""Saturated pixels: the fraction at the top of the camera's range, and a warning above a threshold."""

from __future__ import annotations

import warnings

import numpy as np

from napari_ssdpc.errors import SsdpcWarning

__all__ = ["FULL_SCALE_CODES", "saturated_fraction", "warn_saturation"]

#: The top code value of a b-bit camera (2**b - 1, b in 8..16), also in a wider container: a frame
#: whose maximum is one of these may be clipped by the camera.
FULL_SCALE_CODES = frozenset(2**b - 1 for b in range(8, 17))


def saturated_fraction(frame, level=None) -> float:
    """Fraction of pixels at the top of the range: ``level``, else the full scale of an
    integer frame (one of :data:`FULL_SCALE_CODES`).

    Parameters
    ----------
    frame : array_like, (H, W)
        Camera units.
    level : float, optional
        The saturation level.

    Returns
    -------
    float
    """
    a = np.asarray(frame)
    top = level
    if top is None:
        if a.dtype.kind not in "ui" or a.size == 0:
            return 0.0
        top = int(a.max())
        if top not in FULL_SCALE_CODES:
            return 0.0
    return float(np.mean(a >= top))


def warn_saturation(frame, name="frame", level=None, threshold=1e-4, fraction=None) -> float:
    """Warn (SsdpcWarning) with the saturated fraction when it exceeds ``threshold``.

    Parameters
    ----------
    frame : array_like, (H, W)
    name : str
        How the warning names it.
    level : float, optional
        The saturation level.
    threshold : float
        Largest fraction without a warning.
    fraction : float, optional
        The saturated fraction, where already measured (:func:`saturated_fraction`).

    Returns
    -------
    float
        The saturated fraction.
    """
    frac = saturated_fraction(frame, level) if fraction is None else float(fraction)
    if frac > threshold:
        warnings.warn(
            f"{name}: {100 * frac:.3f}% of pixels are saturated; shorten the exposure or lower the illumination",
            SsdpcWarning,
            stacklevel=3,
        )
    return frac
