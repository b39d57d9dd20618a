"""The temporal prior of 'tv' on moving samples: each weight against the per-frame solution (docs/validation.md).

Two series, simulated by our multislice simulator (source step 4) with camera noise and the grid
shifted by (3.7, −2.2) px and rotated by 0.4°, paper optics at condenser NA 0.25 (16 views):

- ``glide``: a cell (8 x 5 x 3.5 µm semi-axes, n 1.34, nucleus n 1.355, in water) gliding
  (2, 1.3, 1.3) µm a frame in (x, y, z) beside a resting 6 µm bead (n 1.34)
  (``simulation.moving.gliding_cell_and_bead``);
- ``shape``: the same cell at rest, its semi-axes oscillating by 25% (``simulation.moving.changing_cell``).

Each is reconstructed by 'tv' over z −40..40 µm every 1 µm (81 planes), warm-started (frame 0
cold, each later frame from where the previous solve ended), once per temporal weight (weight 0:
the per-frame solution). Per weight, over the warm frames 1..T−1:

- background: the std of Δn over the voxels inside the field stop farther than 10 µm from the
  truth's support in that frame, averaged over the frames (and its std over the frames), and the
  flicker: the std over the frames of each voxel that is background in every frame, averaged;
  the same beyond the resolution ("beyond FWHM_z": outside the support grown by 10 µm
  laterally and 20.7 µm along z, so that the objects' own axial elongation does not count as noise);
- the resting object (the bead): the correlation of Δn with the truth blurred to the method's
  resolution, in a box of ±10 µm (x, y) and ±20 µm (z) around it;
- the moving object (the cell): the error of its Δn-weighted centroid (in a box around the true
  cell: its semi-axes + 8 µm in x, y and + 15 µm in z) against the truth's, in every frame; its
  peak Δn against the per-frame solution's; its correlation with the blurred truth in that box.

Writes docs/temporal_prior.json and prints a Markdown table.

    python docs/temporal_prior.py --cache /tmp/cases [--frames 10] [--weights 0 0.25 0.5 1 2 4]
    python docs/temporal_prior.py --cache /tmp/cases --quadratic --series glide --weights 0 1 4 16
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path

import numpy as np
from scipy import ndimage

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import MemorySink
from napari_ssdpc.reconstruction import regularised
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.simulation.moving import changing_cell, gliding_cell_and_bead
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import metrics as an
from napari_ssdpc.validation import truth as vt

HERE = Path(__file__).parent
Z_UM, DZ_UM, NA = (-40.0, 40.0), 1.0, 0.25
#: the resolution the truth is blurred to, (FWHM_z, FWHM_xy) µm (``ssdpc design`` at NA 0.25)
RESOLUTION_UM = (20.7, 3.9)
#: background: farther than this from the truth's support, µm
BACKGROUND_UM = 10.0
#: the second background: farther than BACKGROUND_UM laterally and this along z (one FWHM_z), µm
AXIAL_UM = RESOLUTION_UM[0]
MEDIUM = 1.33


def _box(rec, centre, half):
    """Boolean (Z, Y, X) box of half-widths ``half`` (x, y, z) µm around ``centre`` (x, y, z) µm."""
    z, y, x = np.meshgrid(rec.z_um, rec.y_um, rec.x_um, indexing="ij", sparse=True)
    return (abs(x - centre[0]) <= half[0]) & (abs(y - centre[1]) <= half[1]) & (abs(z - centre[2]) <= half[2])


def _centroid(vol, rec, region):
    """Δn-weighted centroid (x, y, z) µm of the positive part of ``vol`` in ``region``."""
    w = np.clip(vol, 0, None) * region
    z, y, x = np.meshgrid(rec.z_um, rec.y_um, rec.x_um, indexing="ij", sparse=True)
    return np.array([float((w * g).sum() / w.sum()) for g in (x, y, z)])


def truths(phantoms, rec, moving, resting):
    """Per frame: the truth, its blurred copy, the background mask and the objects' boxes."""
    grid = type("Grid", (), {"z_um": rec.z_um, "y_um": rec.y_um, "x_um": rec.x_um})()
    grid.voxel_um = (DZ_UM, rec.pixel_um, rec.pixel_um)
    field = np.broadcast_to(ndimage.binary_erosion(rec.mask, iterations=4), (len(rec.z_um),) + rec.mask.shape)
    out = []
    for p in phantoms:
        truth = vt.truth_volume(p, grid, MEDIUM)
        blurred = vt.truth_volume(p, grid, MEDIUM, blur_um=RESOLUTION_UM)
        far = ndimage.distance_transform_edt(truth == 0, sampling=grid.voxel_um) > BACKGROUND_UM
        # beyond the resolution too: outside the support grown by 10 µm laterally and FWHM_z along z
        scaled = (DZ_UM * BACKGROUND_UM / AXIAL_UM, rec.pixel_um, rec.pixel_um)
        beyond = ndimage.distance_transform_edt(truth == 0, sampling=scaled) > BACKGROUND_UM
        cell = moving(p)
        box = _box(rec, cell.center_um, np.add(cell.semi_axes_um, (8.0, 8.0, 15.0)))
        item = {"truth": truth, "blurred": blurred, "background": far & field, "beyond": beyond & field, "moving": box}
        item["moving_centroid"] = _centroid(truth, rec, box)
        if resting is not None:
            item["resting"] = _box(rec, resting, (10.0, 10.0, 20.0))
        out.append(item)
    return out


def series(rec, job, case, weight):
    """Δn (T, Z, Y, X), seconds and iterations per frame, warm-started, at one temporal weight."""
    config = val.run_config(case.optics, z=Z_UM, dz=DZ_UM, method="tv", tv={"temporal_weight": weight})
    assert rec.adopt(config)
    job = Job(config, job.calibration, job.flat)
    keep = MemorySink(lambda r: (r.delta_n.astype(np.float32), dict(r.settings)))
    report = Pipeline(job, reconstructor=rec).run(case.frame, keep, progress=True, warm_start=True)
    dn = np.stack([keep.frames[t][0] for t in range(len(report.timings))])
    its = [keep.frames[t][1]["tv_iterations_run"] for t in range(len(report.timings))]
    return dn, [tm["reconstruct_s"] for tm in report.timings], its


def measure(dn, truth, rec, base=None):
    """The numbers of one weight (frames 1..T−1; ``base``: the weight-0 Δn for the peak ratio)."""
    warm = range(1, len(dn))
    out = {}
    for key in ("background", "beyond"):
        noise = [float(dn[t][truth[t][key]].std()) for t in warm]
        always = np.logical_and.reduce([truth[t][key] for t in warm])
        out[f"{key}_std"] = float(np.mean(noise))
        out[f"{key}_std_sd"] = float(np.std(noise))
        out[f"{key}_flicker"] = float(dn[1:, always].std(axis=0).mean())
        out[f"{key}_voxels"] = int(always.sum())
    errors, peaks, corr = [], [], []
    for t in range(len(dn)):
        box = truth[t]["moving"]
        errors.append((_centroid(dn[t], rec, box) - truth[t]["moving_centroid"]).tolist())
        peaks.append(float(dn[t][box].max()))
        corr.append(an.correlation(dn[t], truth[t]["blurred"], box))
    out["moving_centroid_error_um"] = errors  # (x, y, z) per frame
    out["moving_centroid_error_max_um"] = float(np.max(np.linalg.norm(errors, axis=1)[1:]))
    out["moving_peak"] = peaks
    out["moving_correlation"] = float(np.mean(corr[1:]))
    if base is not None:
        ratio = np.array(peaks[1:]) / np.array([float(base[t][truth[t]["moving"]].max()) for t in warm])
        out["moving_peak_ratio"] = [float(ratio.min()), float(ratio.max())]
        lag = [_centroid(dn[t], rec, truth[t]["moving"]) - _centroid(base[t], rec, truth[t]["moving"]) for t in warm]
        out["moving_shift_vs_per_frame_max_um"] = float(np.max(np.linalg.norm(lag, axis=1)))
    if "resting" in truth[0]:
        out["resting_correlation"] = float(
            np.mean([an.correlation(dn[t], truth[t]["blurred"], truth[t]["resting"]) for t in warm])
        )
    return out


def quadratic_prox(v, p, mu, gamma, xp=np):
    """argmin_z μ|z| + (g/2)(z − p)² + ½(z − v)² with g = γ/μ (the weight itself): the quadratic
    alternative to :func:`~napari_ssdpc.reconstruction.proximal.prox_two_kinks`."""
    g = np.float32(gamma / mu)
    m, t = (v + g * p) / (1 + g), np.float32(mu) / (1 + g)
    return (m - xp.clip(m, -t, t)).astype(np.float32)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True, help="folder of the simulated series (.npz)")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--weights", type=float, nargs="+", default=[0.0, 0.25, 0.5, 1.0, 2.0, 4.0])
    ap.add_argument("--series", nargs="+", default=["glide", "shape"], choices=["glide", "shape"])
    ap.add_argument(
        "--quadratic", action="store_true", help="the quadratic prior (weight/2)(φ − φ_prev)² instead (its own .json)"
    )
    args = ap.parse_args(argv)
    if args.quadratic:
        regularised.prox_two_kinks = quadratic_prox  # the z₂-step calls it by its module name
    optics = Optics.paper().replace(condenser_na=NA)
    glide = gliding_cell_and_bead(args.frames)
    cases = {
        "glide": (glide, lambda p: ph.Cell(center_um=p.items[0].center_um, semi_axes_um=p.items[0].semi_axes_um)),
        "shape": (changing_cell(args.frames), lambda p: p),
    }
    cases = {k: v for k, v in cases.items() if k in args.series}
    bead = glide[0].items[2].center_um
    rec, results = None, {}
    for name, (phantoms, moving) in cases.items():
        case = val.simulate_case(f"{name}{args.frames}", phantoms, optics, cache_dir=args.cache, source_step=4)
        config = val.run_config(case.optics, z=Z_UM, dz=DZ_UM, method="tv")
        job = Job(config, calibrate(case.white, case.optics), case.flat)
        rec = job.build() if rec is None or not rec.adopt(config) else rec
        truth = truths(phantoms, rec, moving, bead if name == "glide" else None)
        rows, base = {}, None
        for w in args.weights:
            dn, seconds, its = series(rec, job, case, w)
            base = dn if w == 0 else base
            rows[f"{w:g}"] = {
                **measure(dn, truth, rec, None if w == 0 else base),
                "warm_frame_s": float(np.mean(seconds[1:])),
                "warm_iterations": float(np.mean(its[1:])),
            }
        results[name] = rows
    results["machine"] = f"{platform.processor() or platform.machine()}, {len(os.sched_getaffinity(0))} cores"
    name = "temporal_prior_quadratic.json" if args.quadratic else "temporal_prior.json"
    (HERE / name).write_text(json.dumps(results, indent=1))
    head = ["series", "weight", "bg std 1e-6 (sd)", "flicker 1e-6", "beyond FWHM_z: std (sd)", "flicker"]
    head += ["resting corr", "moving corr"]
    head += ["centroid err max µm", "shift vs w0 µm", "peak / w0", "its", "s"]
    print("| " + " | ".join(head) + " |")
    print("|" + " --- |" * len(head))
    for name in cases:
        for w, r in results[name].items():
            ratio = r.get("moving_peak_ratio", [1.0, 1.0])
            print(
                f"| {name} | {w} | {r['background_std'] * 1e6:.2f} ({r['background_std_sd'] * 1e6:.2f}) | "
                f"{r['background_flicker'] * 1e6:.2f} | {r['beyond_std'] * 1e6:.2f} ({r['beyond_std_sd'] * 1e6:.2f}) | "
                f"{r['beyond_flicker'] * 1e6:.2f} | {r.get('resting_correlation', float('nan')):.3f} | "
                f"{r['moving_correlation']:.3f} | {r['moving_centroid_error_max_um']:.2f} | "
                f"{r.get('moving_shift_vs_per_frame_max_um', 0.0):.2f} | {ratio[0]:.2f}-{ratio[1]:.2f} | "
                f"{r['warm_iterations']:.1f} | {r['warm_frame_s']:.2f} |"
            )


if __name__ == "__main__":
    main()
