"""Compare the phase methods 'tv' and 'wotf' on simulated phantoms (docs/validation.md).

Condenser NA 0.3 (or ``--na``), camera noise, a grid shifted by (3.7, −2.2) px and rotated by 0.4°.
Cases: the PMMA bead, two beads, a cell with a nucleus, a weak bead (0.5 rad) and frame 10 of the
moving sample. Writes docs/methods.json (docs/methods_na0.25.json for ``--na 0.25``). Takes about
25 minutes on 2 cores (the simulations are cached in ``--cache``).

    python docs/compare_methods.py --cache /tmp/cases
    python docs/compare_methods.py --cache /tmp/cases --na 0.25
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt

HERE = Path(__file__).parent
RESOLUTION_UM = (20.7, 3.9)  # (R_z, R_xy) of the paper's optics


def bead_rows(res, spheres, medium, wavelength_um):
    rows = []
    for s in spheres:
        m = vt.bead_metrics(res, s, medium)
        rows.append(
            {
                **vt.projected_phase_metrics(res, s, medium, wavelength_um),
                "dn_true": m["dn_true"],
                "dn_peak": m["dn_peak"],
                "depth_error_um": m["centroid_um"][2] - s.center_um[2],
                "peak_depth_error_um": m["peak_z_um"] - s.center_um[2],
                "lateral_error_um": float(
                    np.hypot(m["centroid_um"][0] - s.center_um[0], m["centroid_um"][1] - s.center_um[1])
                ),
                "opd_ratio": m["opd_ratio"],
                "fwhm_x_um": m["fwhm_x_um"],
                "fwhm_z_um": m["fwhm_z_um"],
            }
        )
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cache", default=None, help="folder for the simulated frames")
    p.add_argument("--na", type=float, default=0.3, help="condenser NA")
    args = p.parse_args()
    optics = val.paper_optics(args.na)
    out = {}
    setups = {  # name: (case, z range µm)
        "PMMA bead": ("bead", (-80.0, 80.0)),
        "two beads": ("two-beads", (-80.0, 80.0)),
        "cell": ("cell", (-40.0, 40.0)),
        "weak bead": ("weak-bead", (-40.0, 40.0)),
        "moving sample, frame 10": ("moving-10", (-40.0, 40.0)),
    }
    for name, (key, z) in setups.items():
        phantom = val.CASES[key]()
        case = val.simulate_case(key, phantom, optics, cache_dir=args.cache)
        medium = case.optics.medium_index
        for method in ("wotf", "tv"):
            t0 = time.perf_counter()
            res, _, _ = val.reconstruct_case(case, z=z, stacks=False, method=method)
            seconds = time.perf_counter() - t0
            if isinstance(phantom, ph.Cell):
                m = vt.cell_metrics(res, case.phantom, RESOLUTION_UM)
                row = {k: v for k, v in m.items()}
            else:
                spheres = case.phantom.spheres if hasattr(case.phantom, "spheres") else [case.phantom]
                row = {
                    "beads": bead_rows(res, spheres, medium, optics.wavelength_um),
                    **vt.truth_metrics(res, phantom, medium, RESOLUTION_UM),
                }
            row["seconds"] = seconds
            row["tv"] = {k: v for k, v in res.settings.items() if k.startswith("tv_")}
            out.setdefault(name, {})[method] = row
            print(name, method, json.dumps(row, default=float), flush=True)
    name = "methods.json" if args.na == 0.3 else f"methods_na{args.na:g}.json"
    (HERE / name).write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
