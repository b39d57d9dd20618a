"""How much of an object a reconstruction keeps, and where along z: the measures of the strong-object
validation (docs/validation.md) against a phantom's truth."""

from __future__ import annotations

import numpy as np

from napari_ssdpc.validation.truth import truth_volume

__all__ = ["mass_and_tail", "masses_and_false"]


def mass_and_tail(result, phantom, medium_index: float, margin_um: float = 4.0, tail_um: float = 8.0) -> dict:
    """Integrated Δn of ``result`` over the object's disk against the truth's, and its tail along z.

    Parameters
    ----------
    result : Result
        Δn (z, y, x) on the µm grid ``z_um``, ``y_um``, ``x_um``.
    phantom : Sphere or Cell
        The truth (``center_um``; a sphere's ``diameter_um`` or a cell's ``semi_axes_um``).
    medium_index : float
    margin_um : float
        The disk reaches this far beyond the object's lateral radius, µm (all planes).
    tail_um : float
        Δn farther than this beyond the object's surface along z is its tail, µm.

    Returns
    -------
    dict
        ``integrated``: Σ Δn over the disk / Σ Δn of the truth (∝ dry mass; 1 is exact); ``tail``:
        Σ|Δn| in the disk farther than ``tail_um`` from the object along z over Σ|Δn| within it.
    """
    dn = np.asarray(result.delta_n, float)
    disk, near = _neighbourhood(result, phantom, margin_um, tail_um)
    truth = float(truth_volume(phantom, result, medium_index).sum())
    inside = float(np.abs(dn[near][:, disk]).sum())
    return {
        "integrated": float(dn[:, disk].sum() / truth),
        "tail": float(np.abs(dn[~near][:, disk]).sum() / inside) if inside > 0 else float("inf"),
    }


def _neighbourhood(result, phantom, margin_um: float, tail_um: float):
    """The object's disk (y, x), ``margin_um`` wider than it, and its planes (z,), ``tail_um`` beyond it."""
    yy, xx = np.meshgrid(result.y_um, result.x_um, indexing="ij")
    cx, cy, cz = phantom.center_um
    if hasattr(phantom, "diameter_um"):
        r_xy = r_z = phantom.diameter_um / 2
    else:
        r_xy, r_z = max(phantom.semi_axes_um), phantom.semi_axes_um[2]
    disk = np.hypot(xx - cx, yy - cy) <= r_xy + margin_um
    return disk, np.abs(np.asarray(result.z_um) - cz) <= r_z + tail_um


def masses_and_false(result, spheres, medium_index: float, margin_um: float = 4.0, tail_um: float = 8.0) -> dict:
    """Each sphere's integrated Δn near it against its truth, and the false Δn away from all of them.

    A sphere's neighbourhood is the cylinder ``margin_um`` wider than it laterally and ``tail_um``
    longer than it on either side along z: spheres that share an axis each keep their own.

    Parameters
    ----------
    result : Result
    spheres : sequence of Sphere
        The truth.
    medium_index : float
    margin_um, tail_um : float
        The neighbourhood beyond the sphere, laterally and along z, µm.

    Returns
    -------
    dict
        ``masses``: Σ Δn over each neighbourhood / Σ Δn of that sphere's truth (1 is exact);
        ``centroids_z_um``: each neighbourhood's Δn-weighted depth (the sphere's sign) minus the
        sphere's; ``false``: Σ|Δn| outside every neighbourhood / |Σ Δn| of the truth (the issue's
        "false Δn"; 0 is exact).
    """
    dn = np.asarray(result.delta_n, float)
    zz = np.broadcast_to(np.asarray(result.z_um, float)[:, None, None], dn.shape)
    anywhere = np.zeros(dn.shape, bool)
    total, masses, depths = 0.0, [], []
    for s in spheres:
        disk, planes = _neighbourhood(result, s, margin_um, tail_um)
        near = planes[:, None, None] & disk[None]
        truth = float(truth_volume(s, result, medium_index).sum())
        w = np.clip(dn[near] * np.sign(truth), 0, None)
        masses.append(float(dn[near].sum() / truth))
        depths.append(float((w * zz[near]).sum() / w.sum()) - s.center_um[2] if w.sum() > 0 else float("nan"))
        anywhere |= near
        total += truth
    return {"masses": masses, "centroids_z_um": depths, "false": float(np.abs(dn[~anywhere]).sum() / abs(total))}
