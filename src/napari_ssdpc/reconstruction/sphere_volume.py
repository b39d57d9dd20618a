"""Spheres on a voxel grid, differentiable in their centre, radius and Δn: the sample model of the bead fit.

A sphere of centre c, radius R and index difference Δn fills a voxel in proportion to how much of
it lies inside; here that fraction is approximated by a linear ramp of the distance d from the
centre, f = clip(½ + (R − d) / s, 0, 1), with s the lateral voxel size, averaged over sub-planes
that sample the voxel's depth at a quarter of s (a coarser sampling of the ramp makes the views
ripple as the sphere moves along z, and the fit stop in a ripple). The ramp makes Δn of every voxel continuous
and piecewise differentiable in (c, R), so the fit can follow the gradient of the views' misfit
(:meth:`~napari_ssdpc.physics.views_multislice.ViewsMultislice.misfit`) down to the sphere's
parameters. Overlapping spheres add.

A sphere is the row (x, y, z, R, Δn): µm, µm, µm, µm, dimensionless.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["PARAMETERS", "spheres_gradient", "spheres_volume"]

#: Sub-planes per ramp width along z (at least). With two sub-planes per voxel the misfit of a
#: strong bead rippled by 0.2 noise variances as its centre moved by 0.1 µm (a sub-plane crossing
#: the ramp), a false minimum every 0.25 µm; four per ramp width leave 0.02.
SUB_PLANES_PER_RAMP = 4
#: The parameters of one sphere, in the order of its row.
PARAMETERS = ("x_um", "y_um", "z_um", "radius_um", "delta_n")


def _grid(z_um, y_um, x_um, dz_um: float):
    z, y, x = (np.asarray(a, float) for a in (z_um, y_um, x_um))
    s = float(x[1] - x[0])
    n_sub = max(1, math.ceil(SUB_PLANES_PER_RAMP * dz_um / s - 1e-9))
    offsets = ((np.arange(n_sub) + 0.5) / n_sub - 0.5) * dz_um
    return z, y, x, s, offsets


def _box(sphere, z, y, x, s: float):
    """The slices of the grid that can hold part of a sphere (its bounding box plus the ramp)."""
    cx, cy, cz, r = sphere[:4]
    reach = abs(r) + s

    def span(a, c):
        return slice(int(np.searchsorted(a, c - reach - s)), int(np.searchsorted(a, c + reach + s)))

    return span(z, cz), span(y, cy), span(x, cx)


def _ramp(sphere, z, y, x, s, offsets, box):
    """Per sub-plane: the filled fraction f and the ramp's slope 1/s where it is partial, on ``box``."""
    cx, cy, cz, r = sphere[:4]
    dy2 = (y[box[1]] - cy)[None, :, None] ** 2
    dx2 = (x[box[2]] - cx)[None, None, :] ** 2
    for o in offsets:
        dz = (z[box[0]] + o - cz)[:, None, None]
        d = np.sqrt(dz * dz + dy2 + dx2)
        t = 0.5 + (r - d) / s
        yield np.clip(t, 0.0, 1.0), ((t > 0) & (t < 1)) / s, d, dz


def spheres_volume(spheres, z_um, y_um, x_um, dz_um: float) -> np.ndarray:
    """Δn of every voxel of a grid holding the given spheres.

    Parameters
    ----------
    spheres : array_like, (B, 5)
        One row (x, y, z, R, Δn) per sphere, µm and dimensionless.
    z_um, y_um, x_um : array_like, (Z,), (ny,), (nx,)
        Voxel centres, µm, evenly spaced (x and y with the same step).
    dz_um : float
        Voxel depth, µm.

    Returns
    -------
    ndarray, float32, (Z, ny, nx)
    """
    z, y, x, s, offsets = _grid(z_um, y_um, x_um, dz_um)
    out = np.zeros((len(z), len(y), len(x)), np.float64)
    for sp in np.atleast_2d(np.asarray(spheres, float)):
        box = _box(sp, z, y, x, s)
        for f, *_ in _ramp(sp, z, y, x, s, offsets, box):
            out[box] += f * (sp[4] / len(offsets))
    return out.astype(np.float32)


def spheres_gradient(spheres, grad, z_um, y_um, x_um, dz_um: float) -> np.ndarray:
    """The gradient of a function of the voxels with respect to the spheres' parameters (chain rule).

    Parameters
    ----------
    spheres : array_like, (B, 5)
        As :func:`spheres_volume`.
    grad : ndarray, (Z, ny, nx)
        ∂L/∂Δn of every voxel.
    z_um, y_um, x_um, dz_um
        As :func:`spheres_volume`.

    Returns
    -------
    ndarray, (B, 5)
        ∂L/∂(x, y, z, R, Δn) of every sphere.
    """
    z, y, x, s, offsets = _grid(z_um, y_um, x_um, dz_um)
    grad = np.asarray(grad, float)
    spheres = np.atleast_2d(np.asarray(spheres, float))
    out = np.zeros(spheres.shape)
    for b, sp in enumerate(spheres):
        box = _box(sp, z, y, x, s)
        g = grad[box]
        cx, cy, dn = sp[0], sp[1], sp[4]
        ddx, ddy = (x[box[2]] - cx)[None, None, :], (y[box[1]] - cy)[None, :, None]
        for f, slope, d, dz in _ramp(sp, z, y, x, s, offsets, box):
            # f = clip(½ + (R − d)/s): ∂f/∂R = 1/s, ∂f/∂c = (r − c) / (d s), where the ramp is partial
            gs = g * slope * (dn / len(offsets))
            gd = gs / np.maximum(d, 1e-9)
            out[b] += [np.sum(gd * ddx), np.sum(gd * ddy), np.sum(gd * dz), np.sum(gs), np.sum(g * f) / len(offsets)]
    return out
