"""Regenerate the validation numbers of docs/measurements.md.

    python docs/measurements_validation.py [--cache DIR] [--skip-reconstructions]

1. The phantoms' own Δn, blurred by a Gaussian of the default resolution and with Gaussian noise of
   1/50 of the object's Δn, five noise seeds each: dry mass, volume and centroid against the truth.
2. A 20-frame moving sample (the same truth volumes): one track, centroid errors.
3. Simulated raw frames (paper optics, condenser NA 0.3, camera noise) reconstructed with `tv`
   (z −40..40 µm, dz 1 µm) and measured with the default rule. Simulations are cached in DIR
   (default ~/.cache/napari-ssdpc/measurements); about 20 minutes on 2 cores, most of it simulation.

Writes docs/measurements.json and prints the tables.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy import ndimage

from napari_ssdpc.analysis.objects import DEFAULT_RULE, FWHM_PER_SIGMA, measure_objects
from napari_ssdpc.analysis.table import measure_series
from napari_ssdpc.simulation import moving
from napari_ssdpc.simulation import phantoms as ph

DOCS = Path(__file__).resolve().parent
DX = 0.8456
Z = np.arange(-40.0, 41.0, 1.0)
Y = X = (np.arange(128) - 63.5) * DX
SNR = 50


def truth(phantom):
    """(∫Δn dV µm³, volume of the outer body µm³, Δn-weighted centroid (x, y, z) µm), analytic."""
    parts = phantom.parts(phantom.medium())
    weights = [p.dn.real * 4 / 3 * np.pi * np.prod(p.semi_axes_um) for p in parts]
    centroid = np.average([p.center_um for p in parts], axis=0, weights=weights)
    return float(sum(weights)), float(4 / 3 * np.pi * np.prod(parts[0].semi_axes_um)), centroid


def observed(phantom, seed):
    """The phantom's Δn blurred to the default resolution, with noise of its Δn / SNR."""
    fz, fxy = DEFAULT_RULE.resolution_um
    s = (fz / FWHM_PER_SIGMA, fxy / FWHM_PER_SIGMA / DX, fxy / FWHM_PER_SIGMA / DX)
    dn = ndimage.gaussian_filter(phantom.volume(Z, Y, X).real, s)
    sigma = phantom.parts(phantom.medium())[0].dn.real / SNR
    return dn + np.random.default_rng(seed).normal(0, sigma, dn.shape)


def compare(o, phantom) -> dict:
    mass, volume, centroid = truth(phantom)
    return {
        "dry_mass_ratio": o["integrated_dn_um3"] / mass,
        "volume_ratio": o["volume_um3"] / volume,
        "centroid_error_um": float(np.linalg.norm([o["x_um"], o["y_um"], o["z_um"]] - centroid)),
        "peak_ri": o["peak_ri"],
        # the parts are nested (a nucleus inside its cell): their Δn add up at the peak
        "true_peak_ri": phantom.medium() + sum(p.dn.real for p in phantom.parts(phantom.medium())),
    }


#: name -> (cache key, phantom)
WEAK = {
    "weak bead (6 µm, Δn 0.007, 0.5 rad)": ("weak", ph.weak_bead()),
    "weak bead (12 µm, Δn 0.007, 1.0 rad)": ("bigweak", ph.Sphere((3.0, -2.0, 5.0), 12.0, 1.525, medium_index=1.518)),
    "weak cell (n 1.34, nucleus 1.345)": ("weakcell", ph.cell(n=1.34, n_nucleus=1.345)),
    "weak moving sample, frame 10 (n 1.34, inclusion 1.36)": (
        "weakmoving10",
        moving.moving_sample(20, n=1.34, n_nucleus=1.36)[10],
    ),
}
STRONG = {
    "cell (n 1.37, nucleus 1.39: 6 rad)": ("cell", ph.cell()),
    "moving sample, frame 10 (n 1.36, inclusion 1.42: 5.4 rad)": ("moving10", moving.moving_sample(20)[10]),
}


def truth_table() -> dict:
    out = {}
    cases = {**WEAK, **STRONG, "moving sample, frame 0": ("", moving.moving_sample(20)[0])}
    for name, (_, phantom) in cases.items():
        runs = []
        for seed in range(5):
            objects = measure_objects(observed(phantom, seed), Z, Y, X, n_medium=phantom.medium())
            runs.append({"objects": len(objects), **compare(objects[0], phantom)})
        out[name] = {k: [r[k] for r in runs] for k in runs[0]}
    return out


def track_table() -> dict:
    series = moving.moving_sample(20)
    rows = measure_series(((t, observed(p, t)) for t, p in enumerate(series)), Z, Y, X, n_medium=1.33)
    errors = [float(np.linalg.norm([r["x_um"], r["y_um"], r["z_um"]] - truth(p)[2])) for r, p in zip(rows, series)]
    masses = [r["dry_mass_pg"] for r in rows]
    return {
        "frames": len(series),
        "rows": len(rows),
        "tracks": len({r["track"] for r in rows}),
        "centroid_error_um_max": max(errors),
        "centroid_error_um_mean": float(np.mean(errors)),
        "dry_mass_pg_mean": float(np.mean(masses)),
        "dry_mass_pg_true": truth(series[0])[0] / 0.19,
        "dry_mass_spread": float(np.ptp(masses) / np.mean(masses)),
    }


def reconstructed_table(cache: Path) -> dict:
    from napari_ssdpc.validation import cases as val

    out = {}
    for name, (key, phantom) in {**WEAK, **STRONG}.items():
        case = val.simulate_case(key, phantom, val.paper_optics(), cache_dir=cache)
        res, _, _ = val.reconstruct_case(case, z=(-40, 40), dz=1.0)
        objects = measure_objects(res.delta_n, res.z_um, res.y_um, res.x_um, n_medium=phantom.medium())
        out[name] = {"objects": len(objects), **compare(objects[0], phantom)} if objects else {"objects": 0}
        print(name, out[name], flush=True)
    return out


def _span(v) -> str:
    v = np.asarray(v, float)
    if np.isnan(v).any():
        return (
            "NaN (unresolved)"
            if np.isnan(v).all()
            else f"{np.nanmin(v):.2f}-{np.nanmax(v):.2f}, NaN {np.isnan(v).sum()}/5"
        )
    return f"{v.mean():.3f} ± {v.std():.3f} ({v.min():.2f}-{v.max():.2f})"


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--cache", default=str(Path.home() / ".cache" / "napari-ssdpc" / "measurements"))
    p.add_argument("--skip-reconstructions", action="store_true")
    args = p.parse_args()
    out = {"rule": {**DEFAULT_RULE.__dict__}, "snr": SNR, "truth": truth_table(), "track": track_table()}
    print("| object | dry mass / true | volume / true | centroid error (µm) |\n| --- | --- | --- | --- |")
    for name, r in out["truth"].items():
        print(
            f"| {name} | {_span(r['dry_mass_ratio'])} | {_span(r['volume_ratio'])} | "
            f"≤ {max(r['centroid_error_um']):.2f} |"
        )
    print(out["track"])
    if not args.skip_reconstructions:
        out["reconstructed"] = reconstructed_table(Path(args.cache))
        print("| object | dry mass / true | volume / true | centroid error (µm) | peak RI (true) |")
        print("| --- | --- | --- | --- | --- |")
        for name, r in out["reconstructed"].items():
            print(
                f"| {name} | {r['dry_mass_ratio']:.2f} | {r['volume_ratio']:.2f} | {r['centroid_error_um']:.2f} | "
                f"{r['peak_ri']:.4f} ({r['true_peak_ri']:.4f}) |"
            )
    (DOCS / "measurements.json").write_text(json.dumps(out, indent=1, default=float) + "\n")


if __name__ == "__main__":
    main()
