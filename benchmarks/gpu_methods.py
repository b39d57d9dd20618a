"""The phase methods on the CPU and on a GPU, in one process on the same frames (docs/performance.md).

Paper optics at condenser NA 0.25 (16 lit views), the simulated 13 µm PMMA bead of ``ssdpc bench``:
'wotf' and 'tv' over z −60..60 µm every 1 µm (121 planes), 'multislice' over z −30..30 µm in its
region of interest; then the 8-frame moving sample streamed from a TIFF into OME-Zarr with 'wotf'
and with 'tv' warm-started. Per method and device: the build time, the first frame (FFT plans,
CUDA kernels) and the next one, frames/s of the series, and how far the GPU's Δn lies from the
CPU's (max |Δn_gpu − Δn_cpu| / max |Δn_cpu|). With ``--beads``, ``ssdpc beads`` on the PMMA bead
and on the strong beads of docs/beads.md whose frames are in the cache (the seconds of each fit and
every bead it found beside the truth).

    python benchmarks/gpu_methods.py --cache DIR [--json OUT.json] [--devices cpu gpu] [--beads gpu]

The frames come from ``ssdpc bench``'s cache (simulated there when missing).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from napari_ssdpc.backend import get_backend
from napari_ssdpc.calibration import calibrate
from napari_ssdpc.reconstruction.beads import measure_beads
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation.bench import MULTISLICE_CASE, TV_CASE, TV_NA, TV_SERIES_FRAMES, machine, simulated_case
from napari_ssdpc.validation.bench_stages import fast_path, series_stage


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True, help="folder of the simulated frames (ssdpc bench's cache)")
    ap.add_argument("--json", type=Path, default=None, help="write the report here")
    ap.add_argument("--devices", nargs="+", default=["cpu", "gpu"], choices=["cpu", "gpu"])
    ap.add_argument("--no-series", action="store_true", help="skip the 8-frame series")
    ap.add_argument("--no-methods", action="store_true", help="skip the methods' rows")
    ap.add_argument("--methods", nargs="+", default=["wotf", "tv", "multislice"], help="the methods' rows to run")
    ap.add_argument("--beads", nargs="*", default=[], choices=["cpu", "gpu"], help="devices of the bead fits")
    args = ap.parse_args(argv)

    report: dict = {"machine": machine(), "devices": {d: get_backend(d).name for d in args.devices}, "rows": {}}

    def save():  # after every row: a run cut short keeps what it measured
        if args.json:
            args.json.write_text(json.dumps(report, indent=1, default=str))

    case = simulated_case("bench-pmma-bead", TV_NA, args.cache)
    cal = calibrate(case.white, case.optics)
    dn: dict = {}
    for device in [] if args.no_methods else args.devices:
        for name, cfg, repeats in (
            ("wotf", {**TV_CASE, "method": "wotf"}, 3),
            ("tv", TV_CASE, 2),
            ("multislice", MULTISLICE_CASE, 1),
        ):
            if name not in args.methods:
                continue
            t0 = time.perf_counter()
            _, res, info = fast_path(case, cal, cfg, device, stacks=False, repeats=repeats)
            keep = ("build_s", "first_frame_s", "frame_s", "planes", "lit_lenslets")
            row = {k: info[k] for k in keep}
            row["stage_s"] = time.perf_counter() - t0
            for k in ("tv_iterations_run", "multislice_iterations_run", "multislice_seconds", "multislice_device"):
                if k in res.settings:
                    row[k] = res.settings[k]
            dn[(name, device)] = np.asarray(res.delta_n, np.float64)
            report["rows"][f"{name}_{device}"] = row
            print(f"{name:10s} {device}: build {row['build_s']:.2f} s, frame {row['frame_s']:.3f} s", flush=True)
            save()
    for device in args.beads:
        bead_rows(report, args.cache, device, save)
    if "cpu" in args.devices and "gpu" in args.devices and not args.no_methods:
        for name in args.methods:
            a, b = dn[(name, "cpu")], dn[(name, "gpu")]
            report["rows"][f"{name}_gpu"]["max_rel_diff_vs_cpu"] = float(np.abs(a - b).max() / np.abs(a).max())
            report["rows"][f"{name}_gpu"]["speedup_vs_cpu"] = (
                report["rows"][f"{name}_cpu"]["frame_s"] / report["rows"][f"{name}_gpu"]["frame_s"]
            )
    if not args.no_series:
        mcase = simulated_case(f"bench-moving{TV_SERIES_FRAMES}", TV_NA, args.cache, frames=TV_SERIES_FRAMES)
        mcal = calibrate(mcase.white, mcase.optics)
        for device in args.devices:
            for key, method, warm in (("series_wotf", "wotf", False), ("series_tv_warm", "tv", True)):
                cfg = {**TV_CASE, "method": method}
                row = series_stage(mcase, mcal, cfg, device, TV_SERIES_FRAMES, stacks=False, warm_start=warm)
                report["rows"][f"{key}_{device}"] = row
                print(f"{key} {device}: {row['steady_frames_per_s']:.2f} frames/s in steady state", flush=True)
                save()
    save()
    return report


def _bead_cases():
    """The beads of docs/beads.md (validation cases at condenser NA 0.25): name -> (phantom, its spheres)."""
    water = 1.333
    silica = ph.Sphere((0.0, 0.0, 0.0), 5.0, 1.463, medium_index=water)
    ps = ph.Sphere((0.0, 0.0, 4.0), 5.0, 1.593, medium_index=water)
    stacked = [ph.Sphere((0.0, 0.0, z), 5.0, 1.463, medium_index=water) for z in (-12.0, 12.0)]
    return {
        "silica-5um": (silica, [silica]),
        "ps-5um": (ps, [ps]),
        "stacked-silica": (ph.Spheres(stacked, medium_index=water), stacked),
    }


def bead_rows(report: dict, cache: Path, device: str, save) -> None:
    """``measure_beads`` on the bench's PMMA bead and on the cached bead cases, one row each."""
    pmma = simulated_case("bench-pmma-bead", TV_NA, cache)
    cases = [(pmma, [ph.pmma_bead()])]
    for name, (phantom, spheres) in _bead_cases().items():
        if (cache / f"{name}_na{TV_NA:g}_s0.npz").is_file():
            cases.append((val.simulate_case(name, phantom, val.paper_optics(TV_NA), cache_dir=cache), spheres))
    for case, spheres in cases:
        cal = calibrate(case.white, case.optics)
        t0 = time.perf_counter()
        rec = Reconstructor(val.run_config(case.optics, z=(-30, 30), device=device, method="tv"), cal, flat=case.flat)
        t1 = time.perf_counter()
        beads = measure_beads(rec, case.frame)
        t2 = time.perf_counter()
        report["rows"][f"beads_{case.name}_{device}"] = {
            "build_s": t1 - t0,
            "beads_s": t2 - t1,
            "beads": [b.to_dict() for b in beads],
            "truth": [{"centre_um": s.center_um, "diameter_um": s.diameter_um, "ri": s.n} for s in spheres],
        }
        print(f"beads {case.name} {device}: {t2 - t1:.1f} s, {len(beads)} bead(s)", flush=True)
        save()


if __name__ == "__main__":
    main()
