"""'tv' against 'multislice' on strong objects: beads from 0.7 to 15.7 rad, cells (docs/validation.md).

Every case is simulated by our multislice simulator with camera noise and the grid shifted by
(3.7, −2.2) px and rotated by 0.4°, paper optics at condenser NA 0.25, and reconstructed over
z −30..30 µm every 1 µm with the default settings of each method. It records the integrated Δn over
a disk 4 µm wider in radius than the object (all planes) against the truth, the tail (Σ|Δn| farther
than 8 µm beyond the object's surface along z over Σ|Δn| within it), the depth of the peak region,
the peak Δn (beads) or the correlation with the blurred truth (cells), the residual over the noise
and the time. Writes docs/multislice_sweep.json and prints a Markdown table. About 2 hours on 2
cores (the simulations about 4 minutes each, the cells' fits 7-9 minutes).

    python docs/multislice_sweep.py --cache /tmp/cases [--only pmma silica]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt
from napari_ssdpc.validation.mass import mass_and_tail, masses_and_false

HERE = Path(__file__).parent
WATER, OIL = 1.333, 1.518
#: name -> (label, phantom)
CASES = {
    "weak": ("weak bead, 6 µm, Δn +0.01 in oil", ph.Sphere((0.0, 0.0, 0.0), 6.0, 1.528, medium_index=OIL)),
    "weak2": (
        "weak bead, 9 µm, Δn +0.01 in water, z −10",
        ph.Sphere((0.0, 0.0, -10.0), 9.0, 1.343, medium_index=WATER),
    ),
    "mid10": ("bead, 10 µm, Δn +0.04 in water, z +8", ph.Sphere((0.0, 0.0, 8.0), 10.0, 1.373, medium_index=WATER)),
    "pmma": ("PMMA, 13 µm, Δn −0.028 in oil", ph.pmma_bead()),
    "neg8": ("bead, 8 µm, Δn −0.088 in oil, z −6", ph.Sphere((0.0, 0.0, -6.0), 8.0, 1.43, medium_index=OIL)),
    "silica": ("silica-like, 5 µm, Δn +0.13 in water", ph.Sphere((0.0, 0.0, 0.0), 5.0, 1.463, medium_index=WATER)),
    "ps": (
        "polystyrene-like, 5 µm, Δn +0.26 in water, z +4",
        ph.Sphere((0.0, 0.0, 4.0), 5.0, 1.593, medium_index=WATER),
    ),
    "stacked": (
        "two silica-like beads, 5 µm, Δn +0.13 in water, on one axis at z −12 and +12",
        ph.Spheres([ph.Sphere((0.0, 0.0, z), 5.0, 1.463) for z in (-12.0, 12.0)], medium_index=WATER),
    ),
    "cell": ("cell (24 x 16 x 10 µm, Δn +0.04) with a nucleus (+0.02)", ph.cell()),
    "lipid": (
        "cell (Δn +0.03) with a lipid droplet (5 µm, +0.1)",
        ph.cell(n=1.36, n_nucleus=1.46, nucleus_semi_axes_um=(2.5, 2.5, 2.5), nucleus_offset_um=(-3.0, 1.0, 1.0)),
    ),
}
Z_UM = (-30.0, 30.0)
#: the resolution the cells' truth is blurred to, (FWHM_z, FWHM_xy) µm
RESOLUTION_UM = (20.7, 3.9)


def measure(res, phantom, medium) -> dict:
    """Integrated Δn, tail, depth and peak (or correlation) of a result against its phantom; for
    beads also each one's mass near it and the false Δn away from them."""
    if isinstance(phantom, ph.Spheres):
        return masses_and_false(res, phantom.spheres, medium)
    cx, cy, cz = phantom.center_um
    bead = isinstance(phantom, ph.Sphere)
    out = mass_and_tail(res, phantom, medium)
    if bead:
        out.update(masses_and_false(res, [phantom], medium))
    if bead:
        m = vt.bead_metrics(res, phantom, medium)
        out.update(
            centroid_z=m["centroid_um"][2] - cz, dn_peak=m["dn_peak"], dn_true=m["dn_true"], ri_centre=m["ri_centre"]
        )
    else:
        pos = res.delta_n.astype(float).clip(0)
        out["centroid_z"] = float((pos.sum(axis=(1, 2)) * res.z_um).sum() / pos.sum()) - cz
        out.update({k: float(v) for k, v in vt.cell_metrics(res, phantom, RESOLUTION_UM).items() if np.isscalar(v)})
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cache", default=None, help="folder for the simulated frames")
    p.add_argument("--only", nargs="*", choices=list(CASES), help="these cases only")
    args = p.parse_args()
    rows = []
    for name in args.only or CASES:
        label, phantom = CASES[name]
        case = val.simulate_case(name, phantom, val.paper_optics(0.25), cache_dir=args.cache)
        medium = case.optics.medium_index
        one = phantom.spheres[0] if isinstance(phantom, ph.Spheres) else phantom  # the phase through one bead
        cx, cy, cz = one.center_um
        g = np.arange(-20.0, 20.25, 0.25)
        dn = np.real(one.volume(cz + g, cy + g, cx + g, medium_index=medium))
        phase = float(np.abs(dn.sum(axis=0)).max()) * 0.25 * 2 * math.pi / case.optics.wavelength_um
        for method in ("tv", "multislice"):
            t0 = time.perf_counter()
            res, _, _ = val.reconstruct_case(case, z=Z_UM, method=method)
            s = res.settings
            rows.append(
                {
                    "case": name,
                    "label": label,
                    "phase_rad": phase,
                    "method": method,
                    "seconds": time.perf_counter() - t0,
                    "residual_over_noise": s.get(f"{'tv' if method == 'tv' else 'multislice'}_residual_over_noise"),
                    "iterations": s.get("multislice_iterations_run"),
                    **measure(res, phantom, medium),
                }
            )
            print(json.dumps(rows[-1]), flush=True)
    (HERE / "multislice_sweep.json").write_text(json.dumps(rows, indent=1))
    print(
        "| sample (phase through it) | method | integrated Δn | tail | centroid z µm | peak Δn (truth) or correlation |"
        " false Δn | residual / noise | iterations, time |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        first = f"{r['label']} ({r['phase_rad']:.1f} rad)" if r["method"] == "tv" else ""
        its = f"{r['iterations']}, " if r["iterations"] is not None else ""
        false = f"{r['false']:.2f}" if "false" in r else ""
        if "integrated" in r:
            peak = (
                f"{r['dn_peak']:+.3f} ({r['dn_true']:+.3f})"
                if "dn_peak" in r
                else f"corr. {r['correlation_blurred']:.3f}"
            )
            numbers = f"{r['integrated']:.2f} | {r['tail']:.2f} | {r['centroid_z']:+.2f} | {peak}"
        else:  # beads on one axis: each one's mass and depth near it
            masses = " / ".join(f"{m:.2f}" for m in r["masses"])
            depths = " / ".join(f"{d:+.2f}" for d in r["centroids_z_um"])
            numbers = f"{masses} (each) | | {depths} | "
        print(
            f"| {first} | `{r['method']}` | {numbers} | {false} | {r['residual_over_noise']:.1f} | "
            f"{its}{r['seconds']:.0f} s |"
        )


if __name__ == "__main__":
    main()
