"""Whole processes side by side: ours from one raw frame, waveorder's 3D phase from a z-stack, the
same output size (121 x 145 x 145 voxels).

Ours: ``ssdpc reconstruct RAW --calibration C --flat F --method wotf|tv --z -60 60 -o OUT.tif`` on the
bench's PMMA-bead frame (paper optics, condenser NA 0.25, 16 lit views of 145 x 145 px). waveorder's:
a Python process that reads a (121, 145, 145) brightfield stack from TIFF, computes its 3D phase
transfer function (``waveorder.models.phase_thick_3d``, the same wavelength, pixel, NAs and 22 planes
of z padding on each side as ours) and inverts it, Tikhonov (``apply_inverse_transfer_function``) or
TV (the legacy ADMM, ``waveorder.util.single_variable_admm_tv_deconvolution_3D``, its default 20
iterations), then writes the volume to TIFF. Each process is timed from start to exit, the two tools
alternating, ``--repeats`` times; the stack's content does not change their work (fixed iterations).

    python benchmarks/against_waveorder.py --waveorder-python /path/to/venv/bin/python [--json OUT]

waveorder is not a dependency: give the interpreter of an environment that has it (and tifffile).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import tifffile

Z_UM, PAD = (-60.0, 60.0), 22  # 121 planes, padded by 22 on each side as ours (forward.padded_planes)

WAVEORDER = f"""
import sys, numpy as np, tifffile, torch
from waveorder.models import phase_thick_3d
from waveorder import util
stack, out, method = sys.argv[1], sys.argv[2], sys.argv[3]
px, dz, lam, n, na_ill, na_det = (float(v) for v in sys.argv[4:10])
data = torch.as_tensor(tifffile.imread(stack).astype(np.float32))
real_tf, imag_tf = phase_thick_3d.calculate_transfer_function(
    tuple(data.shape), px, dz, lam, {PAD}, n, numerical_aperture_illumination=na_ill,
    numerical_aperture_detection=na_det)
if method == "Tikhonov":
    phase = phase_thick_3d.apply_inverse_transfer_function(data, real_tf, imag_tf, {PAD}).numpy()
else:  # the legacy 3D ADMM, on (y, x, z) arrays
    padded = util.pad_zyx_along_z(data[None], {PAD})[0]
    s0 = np.moveaxis(util.inten_normalization_3D(padded[None])[0].numpy(), 0, -1)
    h = np.moveaxis(real_tf.numpy(), 0, -1)
    phase = np.moveaxis(util.single_variable_admm_tv_deconvolution_3D(s0, h), -1, 0)[{PAD}:-{PAD}]
tifffile.imwrite(out, np.asarray(phase, np.float32))
"""


def _timed(cmd) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--waveorder-python", required=True, help="a Python interpreter with waveorder installed")
    ap.add_argument("--cache", type=Path, default=None, help="ssdpc bench's cache of simulated frames")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    from napari_ssdpc.calibration import calibrate
    from napari_ssdpc.validation.bench import TV_NA, default_cache, machine, simulated_case

    case = simulated_case("bench-pmma-bead", TV_NA, args.cache or default_cache())
    o = case.optics
    report: dict = {"machine": machine(), "rows": {}}
    with tempfile.TemporaryDirectory(prefix="ssdpc-vs-waveorder-") as tmp:
        d = Path(tmp)
        tifffile.imwrite(d / "raw.tif", case.frame)
        tifffile.imwrite(d / "flat.tif", case.flat)
        calibrate(case.white, o).to_json(d / "calibration.json")
        planes = int(round(Z_UM[1] - Z_UM[0])) + 1
        ssdpc = "import sys; from napari_ssdpc.cli.entry import run; sys.exit(run())"  # the `ssdpc` command
        ours = [sys.executable, "-c", ssdpc, "reconstruct", str(d / "raw.tif")]
        ours += ["--calibration", str(d / "calibration.json"), "--flat", str(d / "flat.tif")]
        ours += ["--z", str(Z_UM[0]), str(Z_UM[1]), "--overwrite"]
        (d / "waveorder_phase.py").write_text(WAVEORDER)
        for ours_method, theirs in (("wotf", "Tikhonov"), ("tv", "TV")):
            view_px = _view_pixel_um(d, ours)
            rng = np.random.default_rng(0)
            stack = (1 + 0.01 * rng.standard_normal((planes, 145, 145))).astype(np.float32)
            tifffile.imwrite(d / "stack.tif", stack)
            wo = [args.waveorder_python, str(d / "waveorder_phase.py"), str(d / "stack.tif"), str(d / "wo.tif"), theirs]
            wo += [str(v) for v in (view_px, 1.0, o.wavelength_um, o.medium_index, o.condenser_na, o.objective.na)]
            times: dict = {"ssdpc": [], "waveorder": []}
            for _ in range(args.repeats):
                times["ssdpc"].append(_timed([*ours, "--method", ours_method, "-o", str(d / "ours.ome.tif")]))
                times["waveorder"].append(_timed(wo))
            row = {k: statistics.median(v) for k, v in times.items()}
            row.update(runs=times, ratio=row["waveorder"] / row["ssdpc"], view_pixel_um=view_px)
            shape = tifffile.imread(d / "wo.tif").shape
            row["waveorder_shape"] = list(shape)
            report["rows"][f"{ours_method}_vs_{theirs}"] = row
            print(
                f"ours {ours_method}: {row['ssdpc']:.1f} s, waveorder {theirs}: {row['waveorder']:.1f} s "
                f"({shape}): waveorder {row['ratio']:.2f} x slower",
                flush=True,
            )
            if args.json:
                args.json.write_text(json.dumps(report, indent=1))
    return report


def _view_pixel_um(d: Path, ours) -> float:
    """Our output's lateral voxel, µm (from a first run, which also checks the 121 x 145 x 145 volume)."""
    from napari_ssdpc.analysis.result_files import open_result

    subprocess.run([*ours, "--method", "wotf", "-o", str(d / "probe.ome.tif")], check=True, capture_output=True)
    res = open_result(d / "probe.ome.tif")
    shape = (len(res.z_um), len(res.y_um), len(res.x_um))
    if shape != (121, 145, 145):
        raise SystemExit(f"our volume is {shape}, not 121 x 145 x 145: the comparison needs the same size")
    return float(res.x_um[1] - res.x_um[0])


if __name__ == "__main__":
    main()
