"""The rest of a frame: what the multislice model of a region leaves in the views, solved by 'tv'
over the whole field (docs/nonlinear.md).

The multislice refinement models a region around the strong objects. 'tv' had explained those
objects' views with the first-order model, which cannot, and spread Δn they do not hold over the
field: kept outside the region, that is false Δn. Here the region's modelled views are taken out of
the frame's views (in the region m − (I(Δn) / I0 − 1), elsewhere m) and 'tv', with the sign the
frame's own solve chose, solves what is left: the rest of the sample (weak objects beside the
strong ones, the rest of the field) and, where nothing is left, the noise, which its prior keeps
near zero.
"""

from __future__ import annotations

import math
import time

import numpy as np

__all__ = ["rest_views", "with_rest"]


def rest_views(views, view_mask, predicted, region) -> np.ndarray:
    """The views with the region's modelled objects taken out.

    Parameters
    ----------
    views : ndarray, (K, ny, nx)
        The frame's flat-fielded views (1: direct light only).
    view_mask : ndarray, (K, ny, nx)
        Where each view holds data.
    predicted : ndarray, (K, h, w)
        The model's views I / I0 of the region's Δn on the region's pixels.
    region : (slice, slice)
        The region's rows and columns of the views' grid.

    Returns
    -------
    ndarray, float32, (K, ny, nx)
        m − (I / I0 − 1) in the region, m elsewhere; 0 where a view holds no data.
    """
    rows, cols = region
    out = np.array(views, np.float32, copy=True)
    out[:, rows, cols] -= np.asarray(predicted, np.float32) - 1.0
    return out * np.asarray(view_mask, np.float32)


def with_rest(setup, tv, views, dn, region, predicted, sign: str, progress=None, should_stop=None):
    """The frame's Δn: the region's fit, and 'tv' of what its model leaves in the views
    (:func:`rest_views`) outside the region and added inside it.

    Parameters
    ----------
    setup : Setup
        The method's optics, planes, views' front end and backend.
    tv : TvMethod
        The built 'tv' method of the frame (its operators).
    views : ndarray, float32, (K, ny, nx)
    dn : ndarray, (Z, ny, nx)
        Δn with the region's fit in place.
    region : (slice, slice)
    predicted : ndarray, (K, h, w)
        The model's views I / I0 of the region's Δn, on the backend (the report's).
    sign : str
        The sign the frame's 'tv' solve took.
    progress, should_stop : callable, optional

    Returns
    -------
    dn : ndarray, float32, (Z, ny, nx)
    report : dict
        ``multislice_rest_residual_over_noise`` and ``multislice_rest_seconds`` (s).
    """
    rows, cols = region
    t0 = time.perf_counter()
    rest = rest_views(views, setup.views.view_mask, setup.backend.to_host(predicted), region)
    phase, rep = tv.rest(rest, sign, progress=progress, should_stop=should_stop)
    out = phase * (setup.optics.wavelength_um / (2 * math.pi * setup.dz_um))  # Δn = λφ/(2π dz)
    out[:, rows, cols] += dn[:, rows, cols]  # what the region's fit left unexplained is kept there too
    return out, {
        "multislice_rest_residual_over_noise": rep.residual_over_noise,
        "multislice_rest_seconds": time.perf_counter() - t0,
    }
