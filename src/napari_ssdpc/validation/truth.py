"""Measurements of a reconstruction against its phantom's truth: the truth on the result's grid,
and the numbers the validation reports for beads, bars and cells.

Used with :mod:`napari_ssdpc.validation.cases` by the slow tests and the docs' scripts.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from napari_ssdpc.validation import metrics as an


def truth_volume(phantom, result, medium_index, blur_um=None):
    """Δn of the phantom on the reconstruction grid; optionally Gaussian-blurred to the
    system resolution ``blur_um`` = (FWHM_z, FWHM_xy).

    Parameters
    ----------
    phantom : Phantom
    result : Result
        Its z, y, x coordinates (µm) give the grid.
    medium_index : float
    blur_um : (float, float), optional
        (FWHM_z, FWHM_xy), µm.

    Returns
    -------
    ndarray, float32, (Z, Y, X)
        Real part of Δn (unitless).
    """
    vol = np.real(phantom.volume(result.z_um, result.y_um, result.x_um, medium_index=medium_index))
    if blur_um is not None:
        dz, dy, dx = result.voxel_um
        s = [blur_um[0] / 2.355 / dz, blur_um[1] / 2.355 / dy, blur_um[1] / 2.355 / dx]
        vol = ndimage.gaussian_filter(vol, s, mode="constant")
    return vol.astype(np.float32)


def _index(result, point):
    z, y, x = point
    return (
        int(np.argmin(abs(result.z_um - z))),
        int(np.argmin(abs(result.y_um - y))),
        int(np.argmin(abs(result.x_um - x))),
    )


def bead_metrics(result, sphere, medium_index) -> dict:
    """RI at the centre, centroid, lateral/axial FWHM and the z-integrated Δn through the centre.

    Parameters
    ----------
    result : Result
    sphere : Sphere
        The truth.
    medium_index : float

    Returns
    -------
    dict
        ``dn_true``, ``dn_centre``, ``ri_centre``, ``dn_peak``, ``centroid_um`` (x, y, z),
        ``peak_z_um``, ``fwhm_x_um``, ``fwhm_y_um``, ``fwhm_z_um`` (µm), ``opd_ratio``
        (reconstructed / true Δn·d along z through the centre) and ``profiles`` (x, y, z).
    """
    x, y, z = sphere.center_um
    sign = 1 if np.real(sphere.n) > medium_index else -1
    dn = result.delta_n
    coords = (result.z_um, result.y_um, result.x_um)
    seed = _index(result, (z, y, x))
    # the extremum of the right sign nearest the bead: search a box of ±1 diameter laterally
    cz, cy, cx = an.centroid(dn, coords, sign=sign, seed=_local_extremum(dn, seed, sign, sphere, result))
    zp = an.line_through(dn, coords, (z, y, x), 0)
    xp = an.line_through(dn, coords, (z, y, x), 2)
    yp = an.line_through(dn, coords, (z, y, x), 1)
    peak_z = float(zp[0][np.argmax(sign * zp[1])])
    d = float(sphere.diameter_um)
    opd_true = (np.real(sphere.n) - medium_index) * d
    return {
        "dn_true": float(np.real(sphere.n) - medium_index),
        "dn_centre": float(dn[seed]),
        "ri_centre": float(medium_index + dn[seed]),
        "dn_peak": float(zp[1][np.argmax(sign * zp[1])]),
        "centroid_um": (float(cx), float(cy), float(cz)),
        "peak_z_um": peak_z,
        "fwhm_x_um": an.fwhm(*xp),
        "fwhm_y_um": an.fwhm(*yp),
        "fwhm_z_um": an.fwhm(*zp),
        "opd_ratio": float(np.sum(zp[1]) * result.voxel_um[0] / opd_true),
        "profiles": {"x": xp, "y": yp, "z": zp},
    }


def projected_phase_metrics(result, sphere, medium_index, wavelength_um) -> dict:
    """The 2D projected phase map of a bead against the truth: at its centre, and summed over a
    disk of one diameter (the bead and its blur), which the missing cone does not touch.

    Parameters
    ----------
    result : Result
    sphere : Sphere
        The truth.
    medium_index : float
    wavelength_um : float
        Vacuum wavelength, µm.

    Returns
    -------
    dict
        ``phase_true_rad`` (2π Δn d / λ through the centre), ``phase_centre_ratio`` and
        ``phase_footprint_ratio`` (Σ phase·area over 2π Δn V / λ, V the bead's volume).
    """
    d, dn = float(sphere.diameter_um), float(np.real(sphere.n) - medium_index)
    phi = np.asarray(result.projected_phase, np.float64)
    yy, xx = np.meshgrid(result.y_um, result.x_um, indexing="ij")
    r = np.hypot(xx - sphere.center_um[0], yy - sphere.center_um[1])
    k = 2 * np.pi / wavelength_um
    _, dy, dx = result.voxel_um
    true_centre = k * dn * d
    return {
        "phase_true_rad": true_centre,
        "phase_centre_ratio": float(phi[np.unravel_index(np.argmin(r), r.shape)] / true_centre),
        "phase_footprint_ratio": float(np.sum(phi[r <= d]) * dy * dx / (k * dn * np.pi * d**3 / 6)),
    }


def _local_extremum(dn, seed, sign, sphere, result):
    r = max(2, int(round(0.5 * sphere.diameter_um / result.voxel_um[2])))
    iz, iy, ix = seed
    sub = sign * dn[:, max(iy - r, 0) : iy + r + 1, max(ix - r, 0) : ix + r + 1]
    k = np.unravel_index(np.argmax(sub), sub.shape)
    return (int(k[0]), int(k[1] + max(iy - r, 0)), int(k[2] + max(ix - r, 0)))


def bar_metrics(result, target) -> dict:
    """Modulation contrast of each element's vertical bars at the target depth, and the
    best-focus depth (largest absorption variance over the target).

    The contrast is Michelson's (A_bar − A_gap)/(A_bar + A_gap) on the absorption image as it
    is displayed, A = max(μ, 0) (deconvolution ringing below zero shows as black), sampled at
    the bar centres and midway between them: 1 for clean bars, 0 when they merge.

    Parameters
    ----------
    result : Result
        With ``absorption``.
    target : BarTarget

    Returns
    -------
    dict
        ``contrast`` (period µm -> contrast), ``best_focus_z_um`` and ``focus_energy`` (Z,).
    """
    mu = result.absorption
    iz = int(np.argmin(abs(result.z_um - target.z_um)))
    parts = target.parts(float("nan"))
    vertical = [b for b in parts if b.size_um[1] > b.size_um[0]]
    ys = [b.center_um[1] for b in vertical]
    x0, x1 = min(b.center_um[0] for b in vertical) - 5, max(b.center_um[0] for b in vertical) + 5
    y0, y1 = min(ys) - 12, max(ys) + 12
    box = (slice(None), slice(*np.searchsorted(result.y_um, [y0, y1])), slice(*np.searchsorted(result.x_um, [x0, x1])))
    energy = np.var(mu[box], axis=(1, 2))
    contrast = {}
    for k, p in enumerate(target.period_um):
        bars = vertical[3 * k : 3 * k + 3]
        xs = sorted(b.center_um[0] for b in bars)
        yv = bars[0].center_um[1]
        iy = int(np.argmin(abs(result.y_um - yv)))
        band = mu[iz, iy - 2 : iy + 3].mean(axis=0)
        a_bar = max(float(np.mean([np.interp(x, result.x_um, band) for x in xs])), 0.0)
        a_gap = max(float(np.mean([np.interp(0.5 * (a + b), result.x_um, band) for a, b in zip(xs[:-1], xs[1:])])), 0.0)
        contrast[float(p)] = (a_bar - a_gap) / (a_bar + a_gap) if a_bar + a_gap > 0 else float("nan")
    return {"contrast": contrast, "best_focus_z_um": float(result.z_um[int(np.argmax(energy))]), "focus_energy": energy}


def cell_metrics(result, cell, resolution_um) -> dict:
    """Correlation with the truth blurred to the system resolution; RI inside the nucleus.

    Parameters
    ----------
    result : Result
    cell : Cell
        The truth.
    resolution_um : (float, float)
        (FWHM_z, FWHM_xy), µm.

    Returns
    -------
    dict
        Those of :func:`truth_metrics`, and ``ri_nucleus``, ``ri_nucleus_true`` and
        ``ri_nucleus_blurred_truth``.
    """
    n_med = float(cell.medium_index)
    m = truth_metrics(result, cell, n_med, resolution_um)
    blurred = truth_volume(cell, result, n_med, blur_um=resolution_um)
    parts = cell.parts(n_med)
    nucleus = np.abs(np.real(parts[1].delta_n(*np.meshgrid(result.z_um, result.y_um, result.x_um, indexing="ij")))) > 0
    return {
        **m,
        "ri_nucleus": float(n_med + result.delta_n[nucleus].mean()),
        "ri_nucleus_true": float(np.real(cell.n_nucleus)),
        "ri_nucleus_blurred_truth": float(n_med + blurred[nucleus].mean()),
    }


def truth_metrics(result, phantom, medium_index, resolution_um, radius_um=50.0) -> dict:
    """Whole-volume comparison with the truth, within ``radius_um`` of the optical axis.

    Parameters
    ----------
    result : Result
    phantom : Phantom
        The truth.
    medium_index : float
    resolution_um : (float, float)
        (FWHM_z, FWHM_xy) the truth is blurred to, µm.
    radius_um : float
        Radius of the compared cylinder, µm.

    Returns
    -------
    dict
        ``correlation_blurred`` and ``correlation_truth`` (Pearson, over the cylinder),
        ``optical_volume_ratio`` (Σ Δn over the cylinder, reconstructed over true: the ratio of the
        dry masses) and ``depth_error_um`` (centroid of the peak region, reconstructed minus true).
    """
    truth = truth_volume(phantom, result, medium_index)
    blurred = truth_volume(phantom, result, medium_index, blur_um=resolution_um)
    fov = np.hypot(*np.meshgrid(result.y_um, result.x_um, indexing="ij")) < radius_um
    mask = np.broadcast_to(fov, truth.shape)
    coords = (result.z_um, result.y_um, result.x_um)
    sign = 1 if np.sum(truth) >= 0 else -1
    return {
        "correlation_blurred": an.correlation(result.delta_n, blurred, mask),
        "correlation_truth": an.correlation(result.delta_n, truth, mask),
        "optical_volume_ratio": float(np.sum(result.delta_n * mask) / np.sum(truth * mask)),
        "depth_error_um": float(an.centroid(result.delta_n, coords, sign)[0] - an.centroid(truth, coords, sign)[0]),
    }
