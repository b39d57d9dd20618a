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
    fig.savefig(path, dpi=90, metadata={"Software": SOFTWARE})
    plt.close(fig)
    return path


def bead_figure(result, sphere, medium_index, path, title=""):
    """xy, xz and yz slices of the RI through the bead centre, plus lateral and axial RI profiles
    against the ground truth.

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
    plt = _plt()
    ri = result.ri
    truth, (iz, iy, ix) = _truth_and_centre(result, sphere, medium_index)
    lim = max(float(np.abs(ri - medium_index).max()), 1e-6)
    kw = dict(cmap="RdBu_r", vmin=medium_index - lim, vmax=medium_index + lim)
    tv = result.convergence.get("tv") if isinstance(result.convergence, dict) else None
    panels = 6 if tv else 5
    fig, ax = plt.subplots(1, panels, figsize=(3.8 * panels, 3.9), constrained_layout=True)
    ax[0].imshow(ri[iz], extent=(result.x_um[0], result.x_um[-1], result.y_um[-1], result.y_um[0]), **kw)
    ax[1].imshow(
        ri[:, iy, :], extent=(result.x_um[0], result.x_um[-1], result.z_um[-1], result.z_um[0]), aspect="auto", **kw
    )
    im = ax[2].imshow(
        ri[:, :, ix], extent=(result.y_um[0], result.y_um[-1], result.z_um[-1], result.z_um[0]), aspect="auto", **kw
    )
    fig.colorbar(im, ax=ax[2], label="refractive index")
    for a, t, lab in zip(
        ax[:3],
        (f"xy at z = {result.z_um[iz]:g} µm", "xz", "yz"),
        (("x (µm)", "y (µm)"), ("x (µm)", "z (µm)"), ("y (µm)", "z (µm)")),
    ):
        a.set_title(t)
        a.set_xlabel(lab[0])
        a.set_ylabel(lab[1])
    ax[3].plot(result.x_um, ri[iz, iy], label="reconstruction")
    ax[3].plot(result.x_um, truth[iz, iy], "k--", label="truth")
    ax[3].set_xlabel("x (µm)")
    ax[3].set_ylabel("refractive index")
    ax[3].set_title("lateral profile")
    ax[3].legend(fontsize=8)
    ax[4].plot(result.z_um, ri[:, iy, ix], label="reconstruction")
    ax[4].plot(result.z_um, truth[:, iy, ix], "k--", label="truth")
    ax[4].set_xlabel("z (µm)")
    ax[4].set_title("axial profile")
    if tv:  # the TV solver's convergence: objective and relative change per ADMM iteration
        it = np.arange(1, len(tv["objective"]) + 1)
        ax[5].semilogy(it, np.asarray(tv["objective"]) / tv["objective"][0], label="objective / start")
        ax[5].semilogy(it, tv["relative_change"], label="relative change of φ")
        ax[5].set_xlabel("ADMM iteration")
        ax[5].set_title(f"TV solve ({result.settings.get('tv_sign', '')})", fontsize=8)
        ax[5].legend(fontsize=8)
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
