"""Measurements on reconstructed volumes: profiles, FWHM, centroids, correlation with truth."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def fwhm(x, y) -> float:
    """Full width at half maximum of the main peak of ``y(x)`` (linear interpolation).
    A negative-going peak (e.g. Δn of a low-index bead) is measured on −y.

    Parameters
    ----------
    x, y : ndarray, 1D

    Returns
    -------
    float
        In the unit of ``x`` (NaN without a half-maximum crossing).
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if abs(y.min()) > abs(y.max()):
        y = -y
    i = int(np.argmax(y))
    half = y[i] / 2
    if not half > 0:
        return float("nan")
    left = i
    while left > 0 and y[left - 1] > half:
        left -= 1
    right = i
    while right < len(y) - 1 and y[right + 1] > half:
        right += 1
    if left == 0 or right == len(y) - 1:
        return float("nan")  # the peak does not fall to half within the range
    xl = np.interp(half, [y[left - 1], y[left]], [x[left - 1], x[left]])
    xr = np.interp(half, [y[right + 1], y[right]], [x[right + 1], x[right]])
    return float(xr - xl)


def peak_region(volume, sign: int = 0, level: float = 0.5, seed=None):
    """Boolean mask of the connected region around the extremum (or ``seed`` index) where
    sign·volume exceeds ``level`` times the extremum; ``sign`` 0 picks the larger |extremum|.

    Parameters
    ----------
    volume : ndarray
    sign : {-1, 0, 1}
        Sign of the peak; 0: that of the larger |extremum|.
    level : float
        Fraction of the peak value that bounds the region.
    seed : tuple of int, optional
        Index of the peak; default the extremum.

    Returns
    -------
    ndarray, bool
        Shaped like ``volume``.
    """
    v = np.asarray(volume, float)
    if sign == 0:
        sign = 1 if v.max() >= -v.min() else -1
    s = sign * v
    seed = tuple(np.unravel_index(np.argmax(s), s.shape)) if seed is None else tuple(seed)
    labels, _ = ndimage.label(s > level * s[seed])
    return labels == labels[seed]


def centroid(volume, coords, sign: int = 0, level: float = 0.5, seed=None) -> np.ndarray:
    """Weighted centroid (in the units of ``coords``, one 1D array per axis) of the peak region.

    Parameters
    ----------
    volume : ndarray
    coords : sequence of ndarray, 1D
        Coordinates of each axis of ``volume``.
    sign, level, seed
        As in :func:`peak_region`.

    Returns
    -------
    ndarray, (ndim,)
        In the axis order of ``volume``.
    """
    v = np.asarray(volume, float)
    mask = peak_region(v, sign, level, seed)
    w = np.abs(v) * mask
    grids = np.meshgrid(*coords, indexing="ij")
    return np.array([float(np.sum(w * g) / np.sum(w)) for g in grids])


def line_through(volume, coords, point, axis: int):
    """Profile of ``volume`` along ``axis`` through the voxel nearest ``point`` (µm per axis).

    Parameters
    ----------
    volume : ndarray
    coords : sequence of ndarray, 1D
        Coordinates of each axis, µm.
    point : sequence of float
        Position per axis, µm.
    axis : int
        Axis of the profile.

    Returns
    -------
    x : ndarray
        ``coords[axis]``.
    values : ndarray
        The profile.
    """
    idx = [int(np.argmin(np.abs(np.asarray(c) - p))) for c, p in zip(coords, point)]
    sl = tuple(slice(None) if a == axis else i for a, i in enumerate(idx))
    return np.asarray(coords[axis]), np.asarray(volume)[sl]


def correlation(a, b, mask=None) -> float:
    """Pearson correlation of two arrays (inside ``mask``).

    Parameters
    ----------
    a, b : ndarray
        Same shape.
    mask : ndarray, bool, optional
        Elements compared; default all.

    Returns
    -------
    float
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if mask is not None:
        a, b = a[mask], b[mask]
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])
