"""Beads measured as beads: every bead of a frame fitted as a sphere (centre, diameter, RI) with the
multislice model of the views.

Microscopists check an instrument with beads of known size and index. A voxel reconstruction of a
strong bead is biased (the first-order 'tv' loses mass and moves it toward the bead's focus); a
sphere has five numbers, and the multislice model of the views
(:class:`~napari_ssdpc.physics.views_multislice.ViewsMultislice`) predicts its views without the
first-order approximation. Here each bead is the sphere (x, y, z, R, Δn) that minimises

    ½ Σ_k ‖W (I_k(spheres) / I0_k − m_k)‖²

(the views' misfit of the multislice fit, with Δn of the voxels from
:mod:`~napari_ssdpc.reconstruction.sphere_volume`), by L-BFGS-B on the gradient the model's adjoint
gives. The misfit of a strong bead has many local minima (each 2π of phase through the bead is one),
so the fit starts from the best of a scan:

1. the candidates are the objects of a first answer (the 'tv' volume): their centre and the radius of
   their footprint;
2. on a coarse model (a source point every 0.08 NA instead of 0.03, 1 µm planes), a scan of radius
   x Δn at the candidate's depth, of depth over ± ``z_search_um`` for the best three, and of radius x
   Δn again at the best depth; the three best distinct starts are fitted on the coarse model;
3. the best two of those are ranked again by their misfit on the full model (the multislice
   settings' sampling, 0.5 µm planes), and the better is fitted there.

Beads whose footprints come near one another are fitted together in one region (their spheres add):
each is scanned with the others held, twice over, and then the starts one wave of phase away for all
of them at once (each Δn one wave through the centre down, kept or up, each depth moved by up to
3 µm) are ranked and the best fitted: a bead on the axis of another sees its light and can settle a
wave away while the other is wrong.
A bead is reported with the residual of the views over its footprint over the noise, and flagged when
the fit did not converge or the model does not explain the views there.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from napari_ssdpc.errors import Cancelled, SsdpcError
from napari_ssdpc.reconstruction.bead import Bead
from napari_ssdpc.reconstruction.bead_groups import GroupFit, stages
from napari_ssdpc.reconstruction.bead_search import Stopped, overlap_groups
from napari_ssdpc.reconstruction.dpc import phase_to_delta_n
from napari_ssdpc.reconstruction.fit_objects import around_bead, bead_candidates, voxel_steps

__all__ = ["SHAPE_MIN_RADIUS_PX", "first_answer", "fit_beads", "measure_beads"]

#: A footprint under this radius (pixels of the views) is too small to judge its shape: a strong
#: 3.6 µm bead whose first answer kept a 1.2 µm footprint read 1.41 (a round one of 1.9-2.9 µm: 1.02-1.08).
SHAPE_MIN_RADIUS_PX = 3.0


def fit_beads(
    measurements,
    views,
    dn,
    z_um,
    *,
    noise: float,
    optics,
    settings,
    z_search_um: float = 12.0,
    min_fraction: float = 0.05,
    iterations: int = 60,
    previous: Sequence[Bead] = (),
    max_elongation: float | None = None,
    delta_n: float | None = None,
    backend=None,
    progress=None,
    should_stop=None,
) -> list[Bead]:
    """Every bead of a frame fitted as a sphere with the multislice model of its views.

    Parameters
    ----------
    measurements : Measurements
        The views' front end (its grid, masks and multislice model).
    views : ndarray, (K, ny, nx)
        The flat-fielded views of the frame.
    dn : ndarray, (Z, ny, nx)
        A first answer for the frame (the 'tv' volume): where the beads are.
    z_um : ndarray, (Z,)
        Its planes, µm.
    noise : float
        The views' noise σ, flat-field units (the 'tv' report's ``tv_noise``).
    optics : Optics
        The medium's index (RI = medium + Δn) and the objective's NA (a bead's footprint in the views).
    settings : MultisliceSettings
        The multislice model's sampling and its stop (the residual a well-explained bead reaches).
    z_search_um : float
        How far above and below the first answer's depth a bead is looked for, µm (a strong
        bead's first-order answer lies toward its focus); a bead's centre stays within the planes
        ``z_um`` (the volume the user gave holds the sample; a sphere start beyond it could not be
        drawn).
    min_fraction : float
        Objects of the first answer with less integrated |Δn| than this fraction of the largest's are
        not taken for beads.
    iterations : int
        Most L-BFGS iterations of each fit.
    previous : sequence of Bead
        The beads of the previous frame of a series: a group of candidates that each lie on one
        of them starts from them on the full model, without the scan, and keeps that fit when
        every bead is explained and within
        :data:`~napari_ssdpc.reconstruction.bead_groups.WARM_TOLERANCE` of its previous residual
        (else the group is searched as in a first frame).
    max_elongation : float, optional
        Objects of the first answer whose footprint is more elongated than this (its long axis over
        its short one) are not taken for beads (a sphere's footprint is round), unless their
        footprint's radius is under :data:`SHAPE_MIN_RADIUS_PX` pixels; None: every object.
    delta_n : float, optional
        Every bead's Δn, when known (beads of a given index, as in the fit of the optics): held, and
        the search is over size and depth alone (a bead one wave of phase off has another Δn).
    backend : {'cpu', 'gpu'} or Backend, optional
    progress : callable, optional
        ``progress(done, total, label)`` after each stage (the scan, the coarse fit of every bead; the
        starts one wave away and the full fit of every group).
    should_stop : callable, optional
        Checked at every evaluation; True stops with :class:`~napari_ssdpc.errors.Cancelled`.

    Returns
    -------
    list of Bead
        Largest first.
    """
    if not (noise > 0 and math.isfinite(noise)):
        raise SsdpcError(f"the views' noise must be a positive number to judge a bead's fit, got {noise}")
    cands, elongation = bead_candidates(dn, z_um, measurements.y_um, measurements.x_um, return_elongation=True)
    if len(cands):
        size = np.abs(cands[:, 4]) * cands[:, 3] ** 3
        keep = size >= min_fraction * size.max()
        if max_elongation is not None:  # a footprint of a few pixels has no shape to judge
            px = abs(float(measurements.x_um[1] - measurements.x_um[0]))
            keep &= (elongation <= max_elongation) | (cands[:, 3] < SHAPE_MIN_RADIUS_PX * px)
        cands = cands[keep]
    groups = overlap_groups(cands, settings.roi_margin_um)
    total = sum(stages(len(g)) for g in groups)
    job = GroupFit(
        measurements,
        views,
        noise,
        optics,
        settings,
        z_search_um,
        (float(np.min(z_um)), float(np.max(z_um))),
        iterations,
        backend,
        should_stop,
        progress,
        total,
        previous=tuple(b for b in previous if not b.note),
        delta_n=delta_n,
    )
    out: list[Bead] = []
    try:
        for g in groups:
            out += job.fit(cands[g])
    except Stopped:
        raise Cancelled("the bead fit was stopped") from None
    voxel = float(np.prod(voxel_steps(z_um, measurements.y_um, measurements.x_um)))
    out = [
        replace(
            b,
            first_answer_ratio=float(np.sum(dn[around_bead(b, z_um, measurements.y_um, measurements.x_um)]))
            * voxel
            / (math.pi / 6 * b.diameter_um**3 * b.delta_n),
        )
        for b in out
    ]
    return sorted(out, key=lambda b: -(b.diameter_um**3) * abs(b.delta_n))


def measure_beads(
    rec, frame, *, result=None, name: str = "frame", progress=None, should_stop=None, **options
) -> list[Bead]:
    """The beads of a raw frame, each fitted as a sphere (the Python API of ``ssdpc beads``).

    Parameters
    ----------
    rec : Reconstructor
        Built for the frame's calibration and flat with the 'tv' method (or its 'multislice'
        refinement): its 'tv' answer says where the beads are.
    frame : array_like, (H, W)
        The raw frame, camera units.
    result : Result, optional
        The 'tv' result of this frame when it is already computed (not solved again).
    name : str
        The frame's name in error messages.
    progress, should_stop
        As :func:`fit_beads`; ``progress`` also follows the 'tv' solve.
    **options
        ``z_search_um``, ``min_fraction``, ``iterations``: see :func:`fit_beads`.

    Returns
    -------
    list of Bead
        Largest first; empty when the frame holds no object.
    """
    views, _ = rec.views.measure(frame, name)
    if result is None:
        dn, noise = first_answer(rec, views, progress, should_stop)
    else:
        dn, noise = result.delta_n, result.settings.get("tv_noise")
    if noise is None:
        raise SsdpcError("the result holds no 'tv' noise estimate: give a result of the 'tv' method, or none")
    settings = rec.config.reconstruction
    return fit_beads(
        rec.views,
        views,
        dn,
        rec.z_um,
        noise=float(noise),
        optics=rec.optics,
        settings=settings.multislice,
        backend=rec.backend,
        progress=progress,
        should_stop=should_stop,
        **options,
    )


def first_answer(rec, views, progress=None, should_stop=None) -> tuple[np.ndarray, float]:
    """The 'tv' answer of a frame's views, where the bead fit looks for beads, and the views' noise.

    Parameters
    ----------
    rec : Reconstructor
        Built with the 'tv' method (or its 'multislice' refinement).
    views : ndarray, (K, H, W)
        The frame's flat-fielded views.
    progress, should_stop
        Follow and stop the solve.

    Returns
    -------
    dn : ndarray, (Z, ny, nx)
        Δn of the 'tv' answer.
    noise : float
        The views' noise σ it estimated, flat-field units.
    """
    tv = rec.method if rec.method.start is None else rec.method.start
    if tv.name != "tv":
        raise SsdpcError(f"the bead fit starts from the 'tv' answer; the reconstructor solves with '{tv.name}'")
    sol = tv.solve(views, progress=progress, should_stop=should_stop)
    return phase_to_delta_n(sol.phase, rec.optics.wavelength_um, rec.dz), sol.report.get("tv_noise")
