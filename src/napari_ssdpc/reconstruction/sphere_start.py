"""The multislice refinement's second start: the objects of the first answer fitted as spheres
(the bead fit) and drawn on the model's grid (docs/nonlinear.md)."""

from __future__ import annotations

import numpy as np

from napari_ssdpc.reconstruction.beads import fit_beads
from napari_ssdpc.reconstruction.nonlinear import Unknowns
from napari_ssdpc.reconstruction.sphere_volume import spheres_volume

__all__ = ["SPHERE_CLEAR_UM", "SPHERE_MAX_ELONGATION", "sphere_starts"]

#: The sphere start clears the first answer this far around each bead's disk, µm, on every plane
#: (a strong bead's first-order answer trails along its axis).
SPHERE_CLEAR_UM = 2.0
#: Objects of the first answer whose projected |Δn| is more elongated than this (long axis over short)
#: are not fitted as spheres: the 'tv' answers of 5 µm beads read 1.02-1.08, of the cells 1.51-1.52,
#: whose bead fit vouched for no sphere and took 55 % of their refinement's time (211 of 381 s).
SPHERE_MAX_ELONGATION = 1.3


def sphere_starts(setup, views, dn, region, model, noise: float, previous=(), progress=None, should_stop=None):
    """The region's start with the beads of the first answer fitted as spheres (``ssdpc beads``).

    Objects whose footprint is not round (:data:`SPHERE_MAX_ELONGATION`: cells) are not fitted. Every
    bead the fit vouches for (converged, explained, apart from the others) replaces the first answer
    in its column (its disk plus :data:`SPHERE_CLEAR_UM`, every plane) by the sphere drawn on
    the model's grid.

    Parameters
    ----------
    setup : Setup
        The method's optics, settings, views' front end, planes and backend.
    views : ndarray, float32, (K, ny, nx)
    dn : ndarray, (Z, ny, nx)
        The first ('tv') answer, Δn.
    region : (slice, slice)
        The model's rows and columns of the views' grid.
    model : ViewsMultislice
        The model of the region (its grid: ``z_um``, ``y_um``, ``x_um``).
    noise : float
        The views' noise σ.
    previous : sequence of Bead
        The beads the previous frame of a series started from (each group of the frame's beads on
        them is fitted from them, without the scan).
    progress, should_stop : callable, optional
        As for :func:`~napari_ssdpc.reconstruction.beads.fit_beads`.

    Returns
    -------
    starts : dict
        {'spheres': the first answer with the spheres in place of the beads, 'spheres alone':
        the spheres in the medium}: Δn on the model's grid, (Z, k·ny, k·nx), on the backend;
        empty when no bead qualifies.
    beads : list of Bead
        Those used.
    """
    s, v, ms = setup, setup.views, setup.settings.multislice
    rows, cols = region
    found = fit_beads(
        v, views, dn, s.z_um, noise=noise, optics=s.optics, settings=ms, previous=previous,
        max_elongation=SPHERE_MAX_ELONGATION, backend=s.backend, progress=progress, should_stop=should_stop,
    )  # fmt: skip
    x_um, y_um = v.x_um[cols], v.y_um[rows]
    used = [
        b for b in found
        if not b.note and x_um[0] < b.centre_um[0] < x_um[-1] and y_um[0] < b.centre_um[1] < y_um[-1]
    ]  # fmt: skip
    if not used:
        return {}, []
    first = np.array(dn[:, rows, cols], np.float32)
    for b in used:
        reach = b.diameter_um / 2 + SPHERE_CLEAR_UM
        first[:, np.hypot(x_um[None, :] - b.centre_um[0], y_um[:, None] - b.centre_um[1]) <= reach] = 0.0
    rows_ = np.array([[*b.centre_um, b.diameter_um / 2, b.delta_n] for b in used])
    drawn = s.backend.asarray(spheres_volume(rows_, model.z_um, model.y_um, model.x_um, s.dz_um).astype(np.float32))
    rest = Unknowns(ms.refine, s.backend.xp).up(s.backend.asarray(first))
    return {"spheres": drawn + rest, "spheres alone": drawn}, used
