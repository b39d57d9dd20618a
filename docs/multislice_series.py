"""'multislice' along a series: a moving strong bead, every frame cold and warm-started (docs/beads.md).

A silica-like 5 µm bead in water (Δn +0.13, 7.9 rad through its centre) moves 1 µm in x, 0.5 µm
in y and 0.5 µm in z per frame. Simulated by our multislice simulator with camera noise and the
grid shifted and rotated (``validation.cases.simulate_case``), paper optics at condenser NA 0.25,
reconstructed over z −30..30 µm with 'multislice' and its defaults: once with every frame cold
(the bead searched for by the scan) and once warm-started (each frame from the previous frame's
solution: 'tv' from its end state, the bead fitted from the previous frame's, the previous answer
ranked as a start). Per frame: the time, the start taken, the fitted bead against the truth and
the false Δn. Writes docs/multislice_series.json and prints a Markdown table.

    python docs/multislice_series.py --cache /tmp/cases [--frames 3]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path

import numpy as np

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import MemorySink
from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation.mass import masses_and_false

HERE = Path(__file__).parent
WATER = 1.333
#: the bead's move per frame, µm (x, y, z)
STEP_UM = (1.0, 0.5, 0.5)


def run(job, rec, case, spheres, warm: bool) -> list[dict]:
    """One pass over the series: per frame its time, start, bead and false Δn."""
    keep = MemorySink(lambda r: r)
    report = Pipeline(job, reconstructor=rec).run(case.frame, keep, progress=True, warm_start=warm)
    rows = []
    for t, timing in enumerate(report.timings):
        res, s = keep.frames[t], keep.frames[t].settings
        [bead] = s["multislice_start_beads"] or [None]
        truth = spheres[t]
        rows.append({
            "t": t,
            "seconds": timing["reconstruct_s"],
            "start": s["multislice_start"],
            "truth_centre_um": list(truth.center_um),
            "centre_um": None if bead is None else list(bead["centre_um"]),
            "delta_n": None if bead is None else bead["delta_n"],
            "diameter_um": None if bead is None else bead["diameter_um"],
            "false": masses_and_false(res, [truth], WATER)["false"],
        })  # fmt: skip
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True, help="folder of the simulated series (.npz)")
    ap.add_argument("--frames", type=int, default=3)
    args = ap.parse_args(argv)
    spheres = [
        ph.Sphere(tuple(float(t * s) for s in STEP_UM), 5.0, 1.463, medium_index=WATER) for t in range(args.frames)
    ]
    case = val.simulate_case(f"moving-silica{args.frames}", spheres, val.paper_optics(0.25), cache_dir=args.cache)
    config = val.run_config(case.optics, z=(-30, 30), method="multislice")
    job = Job(config, calibrate(case.white, case.optics), case.flat)
    rec = job.build()
    runs = {name: run(job, rec, case, spheres, warm) for name, warm in (("cold", False), ("warm", True))}
    load = os.getloadavg()[0]
    out = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {load:.1f}"}
    out |= runs
    (HERE / "multislice_series.json").write_text(json.dumps(out, indent=1))
    print("| frame | truth (µm) | cold: s, bead centre (µm), Δn | warm: s, start, bead centre (µm), Δn |")
    print("| --- | --- | --- | --- |")
    for c, w in zip(runs["cold"], runs["warm"], strict=True):

        def bead(r):
            return f"({', '.join(f'{v:.2f}' for v in r['centre_um'])}), {r['delta_n']:.4f}" if r["centre_um"] else "-"

        truth = ", ".join(f"{v:.1f}" for v in c["truth_centre_um"])
        print(f"| {c['t']} | ({truth}) | {c['seconds']:.1f}, {bead(c)} | {w['seconds']:.1f}, {w['start']}, {bead(w)} |")
    steady = [r["seconds"] for r in runs["warm"][1:]]
    if steady:
        print(f"warm frames after the first: {np.mean(steady):.1f} s on average")


if __name__ == "__main__":
    main()
