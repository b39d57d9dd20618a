"""Warm starts along a series: 'tv' on a moving sample, every frame cold and warm-started (docs/performance.md).

A swimmer (``moving.moving_sample``: a 18 x 10 x 8 µm ellipsoid with an inclusion, in water)
crosses the field, 3.7 µm in x, 1 µm in y and z per frame. Simulated by our multislice
simulator (source step 4) with camera noise and the grid shifted by (3.7, −2.2) px and rotated
by 0.4°, paper optics at condenser NA 0.25 (16 views), reconstructed over z −60..60 µm every
1 µm (121 planes) by 'tv' with its defaults: once with every frame cold (its Tikhonov start,
up to 60 iterations, the sign probed) and once warm-started (each frame from where the previous
frame's solve ended, up to ``warm_iterations``). Per frame: the time to reconstruct, the ADMM
iterations, the correlation of the warm Δn with the cold one and of each with the truth blurred
to the method's resolution, and the object's Δn-weighted centroid against the truth's.
Writes docs/warm_start_series.json and prints a Markdown table.

    python docs/warm_start_series.py --cache /tmp/cases [--frames 20]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import MemorySink
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation import moving
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt

HERE = Path(__file__).parent
Z_UM, DZ_UM, NA = (-60.0, 60.0), 1.0, 0.25
#: the resolution the truth is blurred to, (FWHM_z, FWHM_xy) µm (``ssdpc design`` at NA 0.25)
RESOLUTION_UM = (20.7, 3.9)


def run(job, rec, frames, phantoms, warm: bool):
    """One pass over the series; per frame Δn, the solver's report and the truth metrics."""
    grid = {"z_um": rec.z_um, "y_um": rec.y_um, "x_um": rec.x_um}
    keep = MemorySink(lambda r: (r.delta_n.astype(np.float32), dict(r.solution.report)))
    report = Pipeline(job, reconstructor=rec).run(frames, keep, progress=True, warm_start=warm)
    out = []
    for t, timing in enumerate(report.timings):
        dn, meta = keep.frames[t]
        res = SimpleNamespace(delta_n=dn, voxel_um=(DZ_UM, rec.pixel_um, rec.pixel_um), **grid)
        m = vt.truth_metrics(res, phantoms[t], float(phantoms[t].medium_index), RESOLUTION_UM)
        out.append({"dn": dn, "s": timing["reconstruct_s"], "iterations": meta["tv_iterations_run"], **m})
    return report, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True, help="folder of the simulated series (.npz)")
    ap.add_argument("--frames", type=int, default=20)
    args = ap.parse_args(argv)
    phantoms = moving.moving_sample(args.frames)
    optics = Optics.paper().replace(condenser_na=NA)
    case = val.simulate_case(f"moving{args.frames}", phantoms, optics, cache_dir=args.cache, source_step=4)
    job = Job(val.run_config(case.optics, z=Z_UM, dz=DZ_UM, method="tv"), calibrate(case.white, case.optics), case.flat)
    t0 = time.perf_counter()
    rec = job.build()
    build_s = time.perf_counter() - t0
    runs = {name: run(job, rec, case.frame, phantoms, warm) for name, warm in (("cold", False), ("warm", True))}
    rows = []
    for t in range(args.frames):
        cold, warm = runs["cold"][1][t], runs["warm"][1][t]
        row = {"t": t, "warm_vs_cold_corr": float(np.corrcoef(cold["dn"].ravel(), warm["dn"].ravel())[0, 1])}
        for name, r in (("cold", cold), ("warm", warm)):
            row.update({f"{name}_{k}": v for k, v in r.items() if k != "dn"})
        rows.append(row)
    steady = rows[2:]  # the first frames pay for the FFT plans and, warm, the first cold frame
    summary: dict = {"build_s": build_s, "planes": len(rec.z_um), "views": len(rec.lenslets)}
    for name, (report, _) in runs.items():
        summary[name] = {
            "steady_frame_s": float(np.mean([r[f"{name}_s"] for r in steady])),
            "steady_iterations": float(np.mean([r[f"{name}_iterations"] for r in steady])),
            "frames_per_s": report.frames_per_second,
            "correlation_blurred": [rows[0][f"{name}_correlation_blurred"], rows[-1][f"{name}_correlation_blurred"]],
        }
    summary["min_warm_vs_cold_corr"] = min(r["warm_vs_cold_corr"] for r in rows)
    summary["machine"] = f"{platform.processor() or platform.machine()}, {len(os.sched_getaffinity(0))} cores"
    (HERE / "warm_start_series.json").write_text(json.dumps({"summary": summary, "frames": rows}, indent=1))
    print(json.dumps(summary, indent=1))
    head = ["frame", "cold s", "warm s", "cold its", "warm its", "corr warm/cold", "corr truth cold / warm"]
    print("| " + " | ".join(head + ["depth error cold / warm, µm"]) + " |")
    print("|" + " --- |" * (len(head) + 1))
    for r in rows:
        print(
            f"| {r['t']} | {r['cold_s']:.2f} | {r['warm_s']:.2f} | {r['cold_iterations']} | {r['warm_iterations']} | "
            f"{r['warm_vs_cold_corr']:.4f} | "
            f"{r['cold_correlation_blurred']:.3f} / {r['warm_correlation_blurred']:.3f} | "
            f"{r['cold_depth_error_um']:+.2f} / {r['warm_depth_error_um']:+.2f} |"
        )


if __name__ == "__main__":
    main()
