"""Regenerate the validation numbers and figures of docs/validation.md.

    python docs/make_validation.py [--cache DIR]

Simulates every phantom with the paper's optics (condenser NA 0.3 unless stated), reconstructs it with
both phase methods and both transfer models, and writes docs/validation.json and
docs/images/validation_*.png. Simulations are cached in DIR (default ~/.cache/napari-ssdpc/validation).
Takes about 20-30 minutes on 2 cores, most of it simulation.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from napari_ssdpc.physics import transfer
from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt
from napari_ssdpc.validation.figures import bead_figure

DOCS = Path(__file__).resolve().parent
IMAGES = DOCS / "images"
RESOLUTION = (20.7, 3.9)  # (R_z, R_xy) µm from `ssdpc design`
METHODS = {
    "wotf": dict(method="wotf"),
    "rl-lenslet": dict(method="rl", rl={"model": "lenslet"}),
    "rl-paper": dict(method="rl", rl={"model": "paper"}),
}


def _clean(d):
    if isinstance(d, dict):
        return {str(k): _clean(v) for k, v in d.items() if k not in ("profiles", "focus_energy")}
    if isinstance(d, (list, tuple)):
        return [_clean(v) for v in d]
    if isinstance(d, (np.floating, np.integer)):
        return d.item()
    return d


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--cache", default=str(Path.home() / ".cache" / "napari-ssdpc" / "validation"))
    p.add_argument("--skip-sweep", action="store_true")
    args = p.parse_args()
    IMAGES.mkdir(exist_ok=True)
    optics = val.paper_optics()
    out = {"condenser_na": optics.condenser_na, "cases": {}, "sweep": {}}
    t0 = time.perf_counter()

    # --- PMMA bead, both condenser settings, every method
    for na in (0.1, val.VALIDATION_NA):
        case = val.simulate_case("bead", ph.pmma_bead(), optics.replace(condenser_na=na), cache_dir=args.cache)
        out["cases"][f"bead_na{na:g}"] = {"simulation_s": case.seconds}
        for mname, kw in METHODS.items():
            res, cal, rec = val.reconstruct_case(case, stacks=False, **kw)
            m = vt.bead_metrics(res, case.phantom, case.optics.medium_index)
            m["reconstruction_s"] = sum(res.timings.values())
            out["cases"][f"bead_na{na:g}"][mname] = _clean(m)
            if mname == "wotf":
                bead_figure(
                    res,
                    case.phantom,
                    case.optics.medium_index,
                    IMAGES / f"validation_bead_na{na:g}.png",
                    f"PMMA bead (13 µm, n 1.49 in 1.518), condenser NA {na:g}, method wotf",
                )
        print("bead", na, time.perf_counter() - t0, flush=True)

    # --- two beads
    case = val.simulate_case("two-beads", ph.two_beads(), optics, cache_dir=args.cache)
    out["cases"]["two-beads"] = {"simulation_s": case.seconds}
    for mname, kw in METHODS.items():
        res, cal, rec = val.reconstruct_case(case, stacks=False, **kw)
        out["cases"]["two-beads"][mname] = [
            _clean(vt.bead_metrics(res, s, case.optics.medium_index)) for s in case.phantom.spheres
        ]
        if mname == "wotf":
            bead_figure(
                res,
                case.phantom.spheres[1],
                case.optics.medium_index,
                IMAGES / "validation_two_beads.png",
                "two beads (6 µm, n 1.56 in 1.518) at z = -25 and +30 µm; slices through the one at +30",
            )
    print("two beads", time.perf_counter() - t0, flush=True)

    # --- cell
    case = val.simulate_case("cell", ph.cell(), optics, cache_dir=args.cache)
    out["cases"]["cell"] = {"simulation_s": case.seconds}
    for mname, kw in METHODS.items():
        res, cal, rec = val.reconstruct_case(case, z=(-40, 40), stacks=False, **kw)
        out["cases"]["cell"][mname] = _clean(vt.cell_metrics(res, case.phantom, RESOLUTION))
    print("cell", time.perf_counter() - t0, flush=True)

    # --- bar target (absorption from the RL stacks)
    case = val.simulate_case("bars", ph.bar_target(), optics, cache_dir=args.cache)
    out["cases"]["bars"] = {"simulation_s": case.seconds}
    for iterations in (40, 15):  # the figure shows the default (15)
        res, cal, rec = val.reconstruct_case(case, z=(0, 80), method="rl", stacks=True, rl={"iterations": iterations})
        m = vt.bar_metrics(res, case.phantom)
        out["cases"]["bars"][f"iterations_{iterations}"] = _clean(m)
    iz = int(np.argmin(abs(res.z_um - case.phantom.z_um)))
    fig, ax = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    ax[0].imshow(res.absorption[iz], cmap="gray_r", extent=(res.x_um[0], res.x_um[-1], res.y_um[-1], res.y_um[0]))
    ax[0].set_title(f"absorption at z = {res.z_um[iz]:g} µm (target at {case.phantom.z_um:g} µm)")
    ax[0].set_xlabel("x (µm)")
    ax[0].set_ylabel("y (µm)")
    ax[1].plot(res.z_um, m["focus_energy"])
    ax[1].axvline(case.phantom.z_um, color="k", ls="--")
    ax[1].set_xlabel("z (µm)")
    ax[1].set_ylabel("variance of absorption over the target")
    fig.savefig(IMAGES / "validation_bars.png", dpi=90)
    plt.close(fig)
    print("bars", time.perf_counter() - t0, flush=True)

    # --- condenser NA sweep: recovered phase of a weak bead and the in-focus DPC transfer
    if not args.skip_sweep:
        weak = ph.Sphere((0.0, 0.0, 0.0), 6.0, 1.528, medium_index=1.518)
        nas = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.38, 0.395)
        for na in nas:
            o = optics.replace(condenser_na=na)
            case = val.simulate_case("weak-bead", weak, o, cache_dir=args.cache)
            res, cal, rec = val.reconstruct_case(case, z=(-60, 60), stacks=False, method="wotf")
            m = vt.bead_metrics(res, weak, 1.518)
            tf = transfer.dpc_transfer_functions(o, rec.lenslets, rec.mask.shape, rec.pixel_um, warn=False)
            out["sweep"][f"{na:g}"] = {
                **_clean(m),
                "dpc_peak": min(tf["contrast"].values()),
                "lit_lenslets": len(rec.lenslets),
                "simulation_s": case.seconds,
            }
            print("sweep", na, time.perf_counter() - t0, flush=True)
        s = out["sweep"]
        x = [float(k) / 0.4 for k in s]
        fig, ax = plt.subplots(1, 3, figsize=(14, 3.8), constrained_layout=True)
        ax[0].plot(x, [v["opd_ratio"] for v in s.values()], "o-")
        ax[0].set_ylabel("recovered / true optical path (z-integrated Δn)")
        ax[1].plot(x, [v["fwhm_z_um"] for v in s.values()], "o-")
        ax[1].set_ylabel("axial FWHM of Δn (µm)")
        ax[2].plot(x, [v["dpc_peak"] for v in s.values()], "o-")
        ax[2].set_ylabel("in-focus peak |H_DPC| (lenslet model)")
        for a in ax:
            a.set_xlabel("σ = condenser NA / objective NA")
            a.axvline(0.75, color="gray", ls=":")
        fig.suptitle("condenser-NA sweep: 6 µm bead, Δn = +0.01 (weak object), objective NA 0.4")
        fig.savefig(IMAGES / "validation_na_sweep.png", dpi=90)
        plt.close(fig)
    out["total_s"] = time.perf_counter() - t0
    (DOCS / "validation.json").write_text(json.dumps(_clean(out), indent=1))
    print(json.dumps(_clean(out), indent=1))


if __name__ == "__main__":
    main()
