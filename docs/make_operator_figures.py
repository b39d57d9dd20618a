"""Figures of docs/operators.md: the source disk over the lenslet sub-apertures, and the DPC
phase transfer functions of the 'lenslet' and 'paper' models.

    python docs/make_operator_figures.py          # writes docs/images/*.png
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import scipy.fft as sfft
from matplotlib.lines import Line2D
from matplotlib.patches import Circle

from napari_ssdpc.physics.dpc_transfer import dpc_transfer_functions
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.transfer import lenslet_case
from napari_ssdpc.settings.optics import Optics

OUT = Path(__file__).resolve().parent / "images"
COLOURS = {"inside": "tab:blue", "straddling": "tab:orange", "outside": "0.6"}
LABELS = {
    "inside": "inside the source: incoherent, absorption only",
    "straddling": "straddling the edge: DPC-like phase contrast",
    "outside": "outside: dark field (2nd order)",
}


def source_over_lenslets(optics: Optics, condenser_nas=(0.1, 0.25)):
    """The MLA as seen on the sensor (y down), in NA units: a/(f_obj m_r) = −λ u_k. The objective
    pupil (black), the condenser disk (gold, symmetric so its inversion does not show) and each
    lenslet's sub-aperture, coloured by its case (docs/conventions.md)."""
    fig, axes = plt.subplots(1, len(condenser_nas), figsize=(5.2 * len(condenser_nas), 5.8))
    lam = optics.wavelength_um
    for ax, na_c in zip(np.atleast_1d(axes), condenser_nas):
        o = optics.replace(condenser_na=na_c)
        ax.add_patch(Circle((0, 0), o.na, fill=False, lw=2, color="k"))
        ax.add_patch(Circle((0, 0), na_c, color="gold", alpha=0.45, lw=0))
        for ln in nominal_lenslets(o):
            c = COLOURS[lenslet_case(o, ln)]
            x, y = -ln.u[0] * lam, -ln.u[1] * lam
            ax.add_patch(Circle((x, y), o.subaperture_na, fill=False, lw=1.6, color=c))
            ax.text(x, y, ",".join(h[0] for h in ln.halves), fontsize=7, ha="center", va="center", color=c)
        ax.set_xlim(-0.48, 0.48)
        ax.set_ylim(0.48, -0.48)  # y down, as on the sensor
        ax.set_aspect("equal")
        ax.set_xlabel("MLA x / (f_obj m_r) = −λ u_x (NA units)")
        ax.set_ylabel("MLA y / (f_obj m_r) = −λ u_y (NA units)")
        ax.set_title(f"condenser NA {na_c} (σ = {o.sigma:.2f}), objective NA {o.na}", fontsize=10)
    handles = [Line2D([], [], color=COLOURS[k], lw=2, label=LABELS[k]) for k in LABELS]
    handles.append(Line2D([], [], color="gold", lw=8, alpha=0.45, label="condenser (source) disk"))
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8)
    fig.suptitle(
        "Source disk over the lenslet sub-apertures; labels: halves of paper Eq. 5 "
        "(u = up, d = down, l = left, r = right)",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0.12, 1, 0.96))
    return fig


def dpc_phase_figure(optics: Optics, shape=(145, 145)):
    """In-focus Im H_DPC,ud of both models, profiles along u_y, and the σ dependence."""
    pix = optics.object_pixel_um
    fy = np.fft.fftshift(sfft.fftfreq(shape[0], pix))
    ext = [fy[0], fy[-1], fy[-1], fy[0]]
    zs = [0.0, 40.0, 80.0]
    fig, axes = plt.subplots(2, 3, figsize=(14, 8.5))
    for col, model in enumerate(("lenslet", "paper")):
        d = dpc_transfer_functions(optics, shape=shape, z_um=zs, model=model)
        h = np.fft.fftshift(d["dpc_phase"]["ud"][0], axes=(-2, -1))
        lim = np.abs(h).max()
        im = axes[0, col].imshow(h.imag, extent=ext, cmap="RdBu_r", vmin=-lim, vmax=lim)
        axes[0, col].set_title(f"'{model}' model, in focus: Im H_DPC (up−down)")
        axes[0, col].set_xlabel("u_x (cycles/µm)")
        axes[0, col].set_ylabel("u_y (cycles/µm)")
        fig.colorbar(im, ax=axes[0, col], shrink=0.8)
        ax = axes[1, col]
        for i, z in enumerate(zs):
            prof = np.fft.fftshift(d["dpc_phase"]["ud"][i][:, 0])
            ax.plot(fy, prof.imag, label=f"Im, z = {z:g} µm", color=f"C{i}")
            ax.plot(fy, prof.real, "--", label=f"Re, z = {z:g} µm", color=f"C{i}", lw=0.8)
        ax.set_xlabel("u_y (cycles/µm) at u_x = 0")
        ax.set_title(f"'{model}' model along u_y (EI band ends at ±{fy[-1]:.2f})")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    nas = np.round(np.arange(0.03, 0.4, 0.01), 3)
    curves = {m: [] for m in ("lenslet", "paper")}
    for na_c in nas:
        o = optics.replace(condenser_na=float(na_c)) if na_c <= 0.32 else _quiet(optics, float(na_c))
        for m in curves:
            curves[m].append(dpc_transfer_functions(o, shape=(97, 97), model=m, warn=False)["contrast"]["ud"])
    ax = axes[0, 2]
    for m, c in curves.items():
        ax.plot(nas / optics.na, c, "o-", ms=3, label=f"'{m}' model")
    ax.axvline(optics.sigma, color="k", lw=0.8, ls=":")
    ax.axhline(0.1, color="r", lw=0.8, ls="--", label="warning threshold")
    ax.set_xlabel("σ = condenser NA / objective NA")
    ax.set_ylabel("in-focus peak |H_DPC| on the EI grid")
    ax.set_title("Phase contrast vs σ (dotted: paper optics)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    axes[1, 2].axis("off")
    fig.tight_layout()
    return fig


def _quiet(optics, na_c):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return optics.replace(condenser_na=na_c)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    optics = Optics.paper()
    source_over_lenslets(optics).savefig(OUT / "source_over_lenslets.png", dpi=130)
    dpc_phase_figure(optics).savefig(OUT / "dpc_phase_tfs.png", dpi=110)
    print(f"wrote {OUT / 'source_over_lenslets.png'} and {OUT / 'dpc_phase_tfs.png'}")


if __name__ == "__main__":
    main()
