"""How much of an object a reconstruction keeps, and where along z: the measures of the strong-object
validation (docs/validation.md) against a phantom's truth."""

from __future__ import annotations

import numpy as np

from napari_ssdpc.validation.truth import truth_volume

__all__ = ["mass_and_tail"]


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
    yy, xx = np.meshgrid(result.y_um, result.x_um, indexing="ij")
    cx, cy, cz = phantom.center_um
    if hasattr(phantom, "diameter_um"):
        r_xy = r_z = phantom.diameter_um / 2
    else:
        r_xy, r_z = max(phantom.semi_axes_um), phantom.semi_axes_um[2]
    disk = np.hypot(xx - cx, yy - cy) <= r_xy + margin_um
    near = np.abs(np.asarray(result.z_um) - cz) <= r_z + tail_um
    truth = float(truth_volume(phantom, result, medium_index).sum())
    inside = float(np.abs(dn[near][:, disk]).sum())
    return {
        "integrated": float(dn[:, disk].sum() / truth),
        "tail": float(np.abs(dn[~near][:, disk]).sum() / inside) if inside > 0 else float("inf"),
    }
