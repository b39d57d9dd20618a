"""The objects of a nonlinear fit's region, each with its own check: where it is, its dry mass and how
well the model explains the views over it (the residual over the noise); the objects of a voxel
answer as the starts of the bead fit, and the voxels around a bead."""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

__all__ = [
    "MIN_VOXELS",
    "OBJECT_LEVEL",
    "around_bead",
    "bead_candidates",
    "explained_limit",
    "fit_objects",
    "object_labels",
    "voxel_steps",
]

#: A voxel belongs to an object when its |Δn| reaches this fraction of the strongest (a pixel of the
#: region's objects, when its z-projected |Δn| does).
OBJECT_LEVEL = 0.15
#: Fewer voxels than this above the level are not an object of the fit's report.
MIN_VOXELS = 8


def explained_limit(stop: float) -> float:
    """The residual over the noise variance beyond which the views of an object (or a pixel) are not
    explained: twice the fit's stop, or twice the noise for a stop below 1.

    Parameters
    ----------
    stop : float
        The fit's stop, residual over the noise variance.

    Returns
    -------
    float
    """
    return 2 * max(stop, 1.0)


def voxel_steps(z_um, y_um, x_um) -> tuple[float, float, float]:
    """A grid's voxel size (dz, dy, dx), µm (dz 1 for a single plane: the volume is per µm of depth).

    Parameters
    ----------
    z_um, y_um, x_um : array_like
        The grid's planes and pixel centres, µm, evenly spaced.

    Returns
    -------
    tuple of float
    """
    dz, dy, dx = (float(abs(a[1] - a[0])) if len(a) > 1 else 1.0 for a in (z_um, y_um, x_um))
    return dz, dy, dx


def object_labels(dn) -> np.ndarray:
    """The objects of a Δn volume: connected voxels (in 3D) whose |Δn| reaches ``OBJECT_LEVEL`` of the
    largest, at least :data:`MIN_VOXELS` of them.

    Parameters
    ----------
    dn : ndarray, (Z, ny, nx)

    Returns
    -------
    ndarray of int, (Z, ny, nx)
        1, 2, ... per object, 0 elsewhere.
    """
    a = np.abs(np.asarray(dn, float))
    if a.max() <= 0:
        return np.zeros(a.shape, int)
    labels, count = ndimage.label(a >= OBJECT_LEVEL * a.max(), structure=np.ones((3, 3, 3)))
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    labels[sizes[labels] < MIN_VOXELS] = 0
    return labels


def fit_objects(dn, misfit_map, z_um, y_um, x_um, *, noise: float, alpha_um3_pg: float, stop: float) -> list[dict]:
    """Every object of a fitted region with its centre, dry mass and residual over the noise.

    The objects are those of :func:`object_labels` (in 3D: two objects on one axis are two); every
    voxel of the region is given to the nearest object, so the masses add up to the region's.

    Parameters
    ----------
    dn : ndarray, (Z, ny, nx)
        The fitted Δn of the region (views' grid).
    misfit_map : ndarray, (ny, nx)
        The squared residual of the views per pixel, averaged over the views with data,
        (flat-field units)².
    z_um, y_um, x_um : ndarray, (Z,), (ny,), (nx,)
        The region's grid, µm.
    noise : float
        The views' noise σ, flat-field units (0: unknown).
    alpha_um3_pg : float
        Specific refraction increment, µm³/pg.
    stop : float
        The fit's stop, in residual over noise: an object whose residual (over its footprint) is
        more than twice it (or than twice the noise, for a stop below 1) is not explained.

    Returns
    -------
    list of dict
        One per object, largest mass first: ``centre_um`` (x, y, z, |Δn|-weighted),
        ``dry_mass_pg``, ``residual_over_noise`` (None when the noise is unknown), ``explained``.
    """
    dn = np.asarray(dn, float)
    z, y, x = (np.asarray(c, float) for c in (z_um, y_um, x_um))
    voxel = voxel_steps(z, y, x)
    a = np.abs(dn)
    labels = object_labels(dn)
    if not labels.any():
        return []
    _, idx = ndimage.distance_transform_edt(labels == 0, sampling=voxel, return_indices=True)
    nearest = labels[tuple(idx)]
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    out = []
    for c in np.unique(labels[labels > 0]):
        own = nearest == c
        w = a[own]
        footprint = (labels == c).any(axis=0)
        ratio = float(np.mean(misfit_map[footprint])) / noise**2 if noise > 0 else None
        out.append(
            {
                "centre_um": [float(g[own] @ w / w.sum()) for g in (xx, yy, zz)],
                "dry_mass_pg": float(dn[own].sum() * np.prod(voxel) / alpha_um3_pg),
                "residual_over_noise": ratio,
                "explained": ratio is None or (math.isfinite(ratio) and ratio <= explained_limit(stop)),
            }
        )
    return sorted(out, key=lambda o: -abs(o["dry_mass_pg"]))


def bead_candidates(dn, z_um, y_um, x_um, return_elongation: bool = False):
    """The objects of a Δn volume as sphere starts (x, y, z, R, Δn).

    Parameters
    ----------
    dn : ndarray, (Z, ny, nx)
        A first answer (e.g. the 'tv' volume), dimensionless.
    z_um, y_um, x_um : ndarray
        Its grid, µm.
    return_elongation : bool
        Also return each footprint's elongation.

    Returns
    -------
    ndarray, (B, 5)
        The |Δn|-weighted centre, the radius of the object's footprint (the disk of its area)
        and the mean Δn of a sphere of that radius holding the object's integrated Δn; largest first.
    elongation : ndarray, (B,)
        With ``return_elongation``: the ratio of the footprint's long axis to its short one (the
        square root of the ratio of its second moments; 1 for a disk: a sphere's footprint is round
        whatever its first answer along z).
    """
    dn = np.asarray(dn, float)
    labels = object_labels(dn)
    z, y, x = (np.asarray(a, float) for a in (z_um, y_um, x_um))
    voxel = float(np.prod(voxel_steps(z, y, x)))
    rows = []
    for c, sl in enumerate(ndimage.find_objects(labels), start=1):
        if sl is None:
            continue
        own = labels[sl] == c
        w = np.abs(dn[sl]) * own
        zz, yy, xx = np.meshgrid(z[sl[0]], y[sl[1]], x[sl[2]], indexing="ij")
        centre = [float(np.sum(g * w) / w.sum()) for g in (xx, yy, zz)]
        foot = own.any(axis=0)
        radius = math.sqrt(foot.sum() * abs(y[1] - y[0]) * abs(x[1] - x[0]) / math.pi)
        integral = float(np.sum(dn[sl] * own)) * voxel
        shape = _elongation(w.sum(axis=0), y[sl[1]], x[sl[2]])
        rows.append([*centre, radius, integral / (4 / 3 * math.pi * radius**3), shape])
    rows.sort(key=lambda r: -abs(r[4]) * r[3] ** 3)
    out = np.array(rows, float).reshape(-1, 6)
    return (out[:, :5], out[:, 5]) if return_elongation else out[:, :5]


def _elongation(weight, y, x) -> float:
    """The long axis of an object's projected |Δn| over its short one, from its weighted second
    moments (1 for a disk or a ring)."""
    yy, xx = np.nonzero(weight)
    if len(yy) < 3:
        return 1.0
    lo, hi = np.linalg.eigvalsh(np.cov(np.stack([x[xx], y[yy]]), aweights=weight[yy, xx]))
    return math.sqrt(hi / lo) if lo > 0 else math.inf


def around_bead(bead, z_um, y_um, x_um) -> np.ndarray:
    """The voxels of a grid around a bead: within 2 µm of its disk laterally and 6 µm of it along z
    (a voxel answer's blur and its trail along the axis).

    Parameters
    ----------
    bead : Bead
        Its ``centre_um`` and ``diameter_um``.
    z_um, y_um, x_um : array_like
        The grid, µm.

    Returns
    -------
    ndarray of bool, (Z, ny, nx)
    """
    x, y, z = bead.centre_um
    r = bead.diameter_um / 2
    lateral = np.hypot(np.asarray(x_um)[None, :] - x, np.asarray(y_um)[:, None] - y) <= r + 2.0
    axial = np.abs(np.asarray(z_um) - z) <= r + 6.0
    return axial[:, None, None] & lateral[None]
