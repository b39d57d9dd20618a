"""Summary figures (matplotlib, Agg): slices through a reconstruction and profiles against the truth."""

from __future__ import annotations

import numpy as np

from napari_ssdpc._version import SOFTWARE


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _truth_and_centre(result, sphere, medium_index):
    """The true RI on the result's grid, and the index (z, y, x) of the voxel at the bead's centre."""
    from napari_ssdpc.validation.truth import _index, truth_volume

    x, y, z = sphere.center_um
    return medium_index + truth_volume(sphere, result, medium_index), _index(result, (z, y, x))


def _save(plt, fig, path, title: str):
    if title:
        fig.suptitle(title)
    fig.savefig(path, metadata={"Software": SOFTWARE})
    plt.close(fig)
    return path


def bead_figure(result, sphere, medium_index, path, title=""):
    """xy, xz and yz slices of the RI through the bead centre (top row), the lateral and axial RI
    profiles against the ground truth and the bead's numbers (bottom row): 1280 x 800 px.

    Parameters
    ----------
    result : Result
    sphere : Sphere
        The truth.
    medium_index : float
    path : str or Path
        The PNG.
    title : str
        Figure title; empty: none.

    Returns
    -------
    str or Path
        ``path``.
    """
    from napari_ssdpc.validation.mass import mass_and_tail
    from napari_ssdpc.validation.truth import bead_metrics

    plt = _plt()
    ri = result.ri
    truth, (iz, iy, ix) = _truth_and_centre(result, sphere, medium_index)
    lim = max(float(np.abs(ri - medium_index).max()), 1e-6)
    kw = dict(cmap="RdBu_r", vmin=medium_index - lim, vmax=medium_index + lim)
    fig, ax = plt.subplots(2, 3, figsize=(12.8, 8.0), dpi=100, constrained_layout=True)
    top, bottom = ax
    x, y, z = result.x_um, result.y_um, result.z_um
    top[0].imshow(ri[iz], extent=(x[0], x[-1], y[-1], y[0]), **kw)
    top[1].imshow(ri[:, iy, :], extent=(x[0], x[-1], z[-1], z[0]), aspect="auto", **kw)
    im = top[2].imshow(ri[:, :, ix], extent=(y[0], y[-1], z[-1], z[0]), aspect="auto", **kw)
    fig.colorbar(im, ax=top[2], label="refractive index")
    for a, t, lab in zip(
        top,
        (f"xy at z = {z[iz]:g} µm", f"xz at y = {y[iy]:.1f} µm", f"yz at x = {x[ix]:.1f} µm"),
        (("x (µm)", "y (µm)"), ("x (µm)", "z (µm)"), ("y (µm)", "z (µm)")),
    ):
        a.set_title(t)
        a.set_xlabel(lab[0])
        a.set_ylabel(lab[1])
    for a, coord, rec, true, name in (
        (bottom[0], x, ri[iz, iy], truth[iz, iy], "lateral profile (x)"),
        (bottom[1], z, ri[:, iy, ix], truth[:, iy, ix], "axial profile (z)"),
    ):
        a.plot(coord, rec, label="reconstruction")
        a.plot(coord, true, "k--", label="truth")
        a.set_xlabel(name.split("(")[1].rstrip(")") + " (µm)")
        a.set_ylabel("refractive index")
        a.set_title(name)
        a.legend()
    m, kept = bead_metrics(result, sphere, medium_index), mass_and_tail(result, sphere, medium_index)
    cx, cy, cz = m["centroid_um"]
    lines = [
        ("RI at the centre", f"{m['ri_centre']:.4f} (truth {sphere.n:.4f})"),
        ("centroid", f"({cx:+.2f}, {cy:+.2f}, {cz:+.2f}) µm"),
        ("FWHM lateral, axial", f"{m['fwhm_x_um']:.1f}, {m['fwhm_z_um']:.1f} µm (diameter {sphere.diameter_um:g})"),
        ("integrated Δn", f"{kept['integrated']:.2f} x the truth"),
        ("tail along z", f"{kept['tail']:.2f} x the bead"),
        ("method", str(result.settings.get("method", ""))),
    ]
    bottom[2].axis("off")
    bottom[2].set_title("the bead, measured")
    for i, (k, v) in enumerate(lines):
        bottom[2].text(0.0, 0.9 - 0.15 * i, k, fontsize=11, transform=bottom[2].transAxes)
        bottom[2].text(0.45, 0.9 - 0.15 * i, v, fontsize=11, transform=bottom[2].transAxes)
    return _save(plt, fig, path, title)


def solver_figure(result, path, title=""):
    """How the iterative solver ran: the objective and the relative change per iteration of every
    solver in ``result.convergence`` ('tv', 'multislice').

    Parameters
    ----------
    result, path, title
        As for :func:`bead_figure`.

    Returns
    -------
    str or Path or None
        ``path``; None when the result holds no iterations (nothing written).
    """
    runs = {
        k: v for k, v in (result.convergence or {}).items() if isinstance(v, dict) and len(v.get("objective", [])) > 1
    }
    if not runs:
        return None
    plt = _plt()
    fig, ax = plt.subplots(
        1, len(runs), figsize=(6.4 * len(runs), 4.5), dpi=100, constrained_layout=True, squeeze=False
    )
    for a, (name, h) in zip(ax[0], runs.items()):
        obj = np.asarray(h["objective"], float)
        a.semilogy(np.arange(1, len(obj) + 1), obj / obj[0], label="objective / start")
        if len(h.get("relative_change", [])):
            a.semilogy(np.arange(1, len(h["relative_change"]) + 1), h["relative_change"], label="relative change")
        a.set_xlabel("iteration")
        a.set_title(f"'{name}' solver")
        a.legend()
    return _save(plt, fig, path, title)


def comparison_figure(results: dict, sphere, medium_index, path, title=""):
    """The same bead by several methods: per method (a row) the xz slice of the RI through the bead
    centre, and the axial and lateral RI profiles against the truth.

    Parameters
    ----------
    results : dict
        {label: Result}, one row each, on the same grid.
    sphere, medium_index, path, title
        As for :func:`bead_figure`.

    Returns
    -------
    str or Path
        ``path``.
    """
    plt = _plt()
    truth, (iz, iy, ix) = _truth_and_centre(next(iter(results.values())), sphere, medium_index)
    lim = max(max(float(np.abs(r.ri - medium_index).max()) for r in results.values()), 1e-6)
    kw = dict(cmap="RdBu_r", vmin=medium_index - lim, vmax=medium_index + lim, aspect="auto")
    rows = len(results)
    fig, ax = plt.subplots(rows, 3, figsize=(12, 3.6 * rows), constrained_layout=True, squeeze=False)
    for row, (label, r) in zip(ax, results.items()):
        im = row[0].imshow(r.ri[:, iy, :], extent=(r.x_um[0], r.x_um[-1], r.z_um[-1], r.z_um[0]), **kw)
        row[0].set(title=f"{label}: xz through the bead", xlabel="x (µm)", ylabel="z (µm)")
        fig.colorbar(im, ax=row[0], label="refractive index")
        row[1].plot(r.z_um, r.ri[:, iy, ix], label=label)
        row[1].plot(r.z_um, truth[:, iy, ix], "k--", label="truth")
        row[1].set(title="axial profile", xlabel="z (µm)", ylabel="refractive index")
        row[2].plot(r.x_um, r.ri[iz, iy], label=label)
        row[2].plot(r.x_um, truth[iz, iy], "k--", label="truth")
        row[2].set(title=f"lateral profile at z = {r.z_um[iz]:g} µm", xlabel="x (µm)")
        row[2].legend(fontsize=8)
    return _save(plt, fig, path, title)
