"""The region of the multislice refinement: where its model lies and what is held there (the
objects' support, the medium edge, the columns a fit leaves unexplained), docs/nonlinear.md."""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.multislice_source import square_roi
from napari_ssdpc.reconstruction.fit_objects import OBJECT_LEVEL, explained_limit, object_labels

__all__ = ["medium_edge", "object_support", "objects_roi", "region_of", "unexplained_columns"]


def objects_roi(dn, x_um, y_um, margin_um: float, level: float = OBJECT_LEVEL):
    """The square region of the views' grid around the objects of a Δn volume, plus a margin.

    Parameters
    ----------
    dn : ndarray, (Z, ny, nx)
        Δn on the views' grid.
    x_um, y_um : ndarray, (nx,), (ny,)
        The grid, µm.
    margin_um : float
        Added on every side, µm (the light an object scatters must stay inside).
    level : float
        Fraction of the strongest projected |Δn| that marks an object.

    Returns
    -------
    rows, cols : slice
    """
    proj = np.abs(dn).sum(axis=0)
    on = proj >= level * proj.max() if proj.max() > 0 else np.ones(proj.shape, bool)
    iy, ix = np.nonzero(on)
    x0, x1, y0, y1 = x_um[ix.min()], x_um[ix.max()], y_um[iy.min()], y_um[iy.max()]
    side = max(x1 - x0, y1 - y0) + 2 * margin_um
    return square_roi(x_um, y_um, ((x0 + x1) / 2, (y0 + y1) / 2), side)


def object_support(dn, voxel_um, margin_um: float) -> np.ndarray:
    """Where a fit's objects are, grown by a margin: 1 within ``margin_um`` of an object voxel.

    Parameters
    ----------
    dn : ndarray, (Z, ny, nx)
        Δn of the region.
    voxel_um : (float, float, float)
        (dz, dy, dx), µm.
    margin_um : float

    Returns
    -------
    ndarray, bool, (Z, ny, nx)
        All True when the fit has no object (nothing is held).
    """
    from scipy import ndimage

    labels = object_labels(dn)
    if not labels.any():
        return np.ones(np.shape(dn), bool)
    return ndimage.distance_transform_edt(labels == 0, sampling=voxel_um) <= margin_um


def unexplained_columns(misfit, noise: float, stop: float, pixel_um: float, margin_um: float) -> np.ndarray:
    """The pixels whose views a fit leaves unexplained, grown by a margin: there the data ask for Δn.

    A pixel is unexplained when its mean squared residual over its 3 x 3 neighbourhood (all views)
    exceeds twice the fit's stop (as for the objects of the report).

    Parameters
    ----------
    misfit : ndarray, (ny, nx)
        The squared residual per pixel, averaged over the views with data, (flat-field units)².
    noise : float
        The views' noise σ (0: unknown, nothing is unexplained).
    stop : float
        The fit's stop, residual over the noise variance.
    pixel_um, margin_um : float

    Returns
    -------
    ndarray, bool, (ny, nx)
    """
    from scipy import ndimage

    if not noise > 0:
        return np.zeros(np.shape(misfit), bool)
    high = ndimage.uniform_filter(np.asarray(misfit, float), 3) > explained_limit(stop) * noise**2
    grow = max(int(round(margin_um / pixel_um)), 0)
    return ndimage.binary_dilation(high, iterations=grow) if grow and high.any() else high


def medium_edge(side: int, pixel_um: float, edge_um: float):
    """1 inside a square region, 0 on its edge band: there Δn is held at the medium.

    The model's grid is periodic, so a Δn that is uniform over a plane of the region is a pure phase
    delay that no view sees, and under a sign constraint the fit pumps it up into a floor; holding
    the region's edge at the medium (Δn 0, as the real sample is around its objects) removes that
    free mean of every plane.

    Parameters
    ----------
    side : int
        The region's side, unknowns.
    pixel_um : float
        The unknowns' lateral pixel, µm.
    edge_um : float
        Width of the band held at the medium, µm.

    Returns
    -------
    ndarray, float32, (1, side, side)
    """
    e = int(math.ceil(edge_um / pixel_um - 1e-9))
    if 2 * e >= side - 1:
        raise SsdpcError(
            f"the multislice region ({side * pixel_um:.1f} µm) leaves nothing free inside its medium edge of "
            f"{edge_um:g} µm on each side: give a larger region (--roi) or a smaller multislice medium_edge_um"
        )
    out = np.zeros((1, side, side), np.float32)
    out[:, e : side - e, e : side - e] = 1.0
    return out


def region_of(box_um, x_um, y_um):
    """The square region of the views' grid that covers a box given in µm.

    Parameters
    ----------
    box_um : (float, float, float, float)
        [x_min, x_max, y_min, y_max], µm.
    x_um, y_um : ndarray, (nx,), (ny,)
        The grid, µm.

    Returns
    -------
    rows, cols : slice
    """
    x0, x1, y0, y1 = box_um
    if x1 < x_um[0] or x0 > x_um[-1] or y1 < y_um[0] or y0 > y_um[-1]:
        raise SsdpcError(
            f"the region {x0:g}..{x1:g} x {y0:g}..{y1:g} µm lies outside the field of view "
            f"({x_um[0]:.1f}..{x_um[-1]:.1f} x {y_um[0]:.1f}..{y_um[-1]:.1f} µm); give a region inside it (--roi)"
        )
    return square_roi(x_um, y_um, ((x0 + x1) / 2, (y0 + y1) / 2), max(x1 - x0, y1 - y0))
