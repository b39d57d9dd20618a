"""The figures of docs/dpc.md: the real Siemens star against the Waller-Lab solver's phase, and an
xz section through simulated beads in a z-stack (`python docs/make_dpc_figures.py`, about a minute)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import tifffile

from napari_ssdpc.reconstruction.led_dpc import reconstruct_dpc
from napari_ssdpc.settings.dpc_optics import DpcOptics
from napari_ssdpc.simulation.led_dpc import simulate_dpc_stack
from napari_ssdpc.simulation.phantoms import Sphere, Spheres

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "dpc_cmat"
OUT = ROOT / "docs" / "images"


def _panel(fig, ax, image, title: str, **shown) -> None:
    """One image with its title, x in µm and a colour bar."""
    h = ax.imshow(image, **shown)
    ax.set_title(title, fontsize=12)
    ax.set_xlabel("x (µm)")
    fig.colorbar(h, ax=ax, shrink=0.8)


def star() -> Path:
    """Raw image, the phase of `ssdpc dpc`, the reference phase and their difference, on the star's centre."""
    images = tifffile.imread(DATA / "testDataset_dpc.tif")
    optics = DpcOptics.from_yaml(DATA / "optics.yaml")
    ours = reconstruct_dpc(images, optics, "tikhonov").phase
    peer = tifffile.imread(DATA / "peer_phase.tif")
    box = (slice(95, 395), slice(295, 595))
    px = optics.pixel_um
    extent = (0, 300 * px, 300 * px, 0)
    corr = np.corrcoef(ours.ravel(), peer.ravel())[0, 1]
    fig, axes = plt.subplots(1, 4, figsize=(16, 4.4), constrained_layout=True)
    panels = (
        (images[0][box], "image 1 (lit half 270°), counts", "gray", None),
        (ours[box], "ssdpc dpc (tikhonov), rad", "gray", (-1.5, 2.5)),
        (peer[box], "Waller-Lab DPC solver, rad", "gray", (-1.5, 2.5)),
        ((ours - peer)[box], f"difference, rad (correlation {corr:.4f})", "RdBu_r", (-0.1, 0.1)),
    )
    for ax, (im, title, cmap, lim) in zip(axes, panels):
        _panel(fig, ax, im, title, cmap=cmap, extent=extent, vmin=lim and lim[0], vmax=lim and lim[1])
    axes[0].set_ylabel("y (µm)")
    fig.suptitle("Phase Siemens star, 40x / 0.4, σ = 1 (Waller-Lab/dpc-cMat test set)", fontsize=13)
    path = OUT / "dpc_star.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def beads() -> Path:
    """xz sections (y = 0) of the truth and of tikhonov and tv on a simulated z-stack of three beads."""
    optics = DpcOptics(
        wavelength_um=0.52, objective_na=0.65, magnification=40.0, camera_pixel_um=6.5, medium_index=1.33,
        illumination_na=0.65, patterns_deg=[0.0, 180.0, 90.0, 270.0], z_um=[float(z) for z in range(-4, 5)],
    )  # fmt: skip
    spec = [((0.0, 0.0, -2.5), 2.5, 1.345), ((0.0, 0.0, 2.5), 2.5, 1.345), ((3.5, 0.0, 0.0), 3.0, 1.34)]
    stack = simulate_dpc_stack(Spheres([Sphere(c, d, n) for c, d, n in spec]), optics, (80, 80), source_spacing_na=0.04)
    x = (np.arange(80) - 39.5) * optics.pixel_um
    results = {m: reconstruct_dpc(stack, optics, m, z_min_um=-6.0, z_max_um=6.0, dz_um=0.5) for m in ("tikhonov", "tv")}
    z = results["tv"].z_um
    zz, xx = np.meshgrid(z, x, indexing="ij")
    truth = np.zeros_like(zz)
    for (cx, _, cz), d, n in spec:
        truth[(xx - cx) ** 2 + (zz - cz) ** 2 <= (d / 2) ** 2] = n - optics.medium_index
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), constrained_layout=True)
    extent = (x[0], x[-1], z[-1], z[0])
    row = 40  # y = 0.08 µm
    panels = [("truth", truth)] + [(m, r.delta_n[:, row, :]) for m, r in results.items()]
    for ax, (title, im) in zip(axes, panels):
        _panel(fig, ax, im, f"{title}: Δn, xz at y = 0", cmap="magma", extent=extent, aspect="auto", vmin=0, vmax=0.015)
    axes[0].set_ylabel("z (µm, > 0 farther from the objective)")
    fig.suptitle("Simulated z-stack, 40x / 0.65 in water, σ = 1: two beads on one axis and a third", fontsize=13)
    path = OUT / "dpc_beads.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


if __name__ == "__main__":
    for made in (star(), beads()):
        print("wrote", made)
