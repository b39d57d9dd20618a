"""What fitting the pupil to a frame of beads buys: two 6 µm beads (Δn 0.03 in water, z −10 and +15 µm)
imaged by an instrument with spherical aberration (c₁₁ 0.224 waves rms, a 0.5 wave coefficient) and
every view defocused by 0.5 waves at its sub-aperture's edge, reconstructed with the nominal optics,
with the optics `ssdpc fit-optics FRAME` fitted to that frame, and with the true optics
(docs/aberrations.md).

The paper's optics in water (n 1.33) at condenser NA 0.25, camera noise, the grid shifted by
(3.7, −2.2) px and rotated by 0.4°; the default method `tv`, z −30..30 µm. Records each bead's
integrated Δn near it against the truth and the depth of its Δn-weighted centroid, the fitted terms
and the fit's time. Writes docs/pupil_fit_validation.json (with ``--condenser``, the condenser also
at NA 0.26 and 0.01 NA off axis: docs/pupil_fit_validation-condenser.json; with ``--only KIND``, one
imperfection alone: ``sph`` the spherical aberration (``sph1`` twice as much: a one-wave
coefficient), ``def`` the views' defocus, ``cond`` the condenser, ``lens`` the lenslets' centres and
focal lengths off by up to 1 %: docs/pupil_fit_validation-KIND.json; with ``--bead-ri`` the beads'
index is given to the fit: ...-KIND-ri.json)
and prints a Markdown table. With ``--cell``, a cell imaged by the same instrument too. With
``--pmma``, the instrument in oil (n 1.518) with all three imperfections: the pupil fitted to two
6 µm PMMA beads (n 1.49, known) and the paper's 13 µm PMMA bead imaged by it on another frame,
reconstructed with each optics (docs/pupil_fit_validation-pmma.json).

    python docs/pupil_fit_validation.py --cache /tmp/cases
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.reconstruction.optics_fit import BeadFrame, fit_optics
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt
from napari_ssdpc.validation.mass import mass_and_tail, masses_and_false

HERE = Path(__file__).parent
MEDIUM = 1.33
Z_UM = (-30.0, 30.0)
SPHERICAL, DEFOCUS = 0.224, 0.5
#: The cell's truth is blurred to this (FWHM_z, FWHM_xy), µm, before it is correlated.
CELL_RESOLUTION_UM = (20.7, 3.9)
BEADS = (ph.Sphere((-20.0, 5.0, -10.0), 6.0, MEDIUM + 0.03), ph.Sphere((20.0, -5.0, 15.0), 6.0, MEDIUM + 0.03))
#: ``--pmma``: the oil, the beads' known index, and the bead frame the pupil is fitted to.
OIL, PMMA_RI = 1.518, 1.49
PMMA_BEADS = tuple(ph.Sphere(b.center_um, b.diameter_um, PMMA_RI, medium_index=OIL) for b in BEADS)


def _lenslets(nominal, lenslets):
    """Each lenslet's sub-aperture off its place by up to 1 % of the pitch (5 µm) and its focal length
    off by up to 1 % (±0.04 waves of defocus at its edge), drawn once (seed 7)."""
    rng = np.random.default_rng(7)
    terms = tuple(
        LensletTerms(
            row=ln.row,
            col=ln.col,
            offset_um=tuple(float(v) for v in rng.uniform(-5, 5, 2)),
            defocus_waves=float(rng.uniform(-0.04, 0.04)),
        )
        for ln in lenslets
    )
    return nominal.replace(aberrations=Aberrations(lenslets=terms))


#: One imperfection alone (``--only``): the optics of the instrument that recorded the frames.
ALONE = {
    "sph": lambda nominal, _: nominal.replace(
        aberrations=Aberrations(objective_zernike_waves=(0.0,) * 10 + (SPHERICAL,))
    ),
    "sph1": lambda nominal, _: nominal.replace(
        aberrations=Aberrations(objective_zernike_waves=(0.0,) * 10 + (2 * SPHERICAL,))
    ),
    "def": lambda nominal, lenslets: nominal.replace(
        aberrations=Aberrations(
            lenslets=tuple(LensletTerms(row=ln.row, col=ln.col, defocus_waves=DEFOCUS) for ln in lenslets)
        )
    ),
    "cond": lambda nominal, _: nominal.replace(
        condenser_na=0.26, aberrations=Aberrations(condenser_offset_na=(0.01, 0.0))
    ),
    "lens": _lenslets,
}


def _reconstructed(case, runs, method: str = "tv"):
    """The case's frame reconstructed by ``method`` with each optics of ``runs``: (how, result, seconds)."""
    for how, (optics, c) in runs.items():
        t0 = time.perf_counter()
        rec = Reconstructor(val.run_config(optics, z=Z_UM, dz=1.0, method=method), c, flat=case.flat)
        yield how, rec.reconstruct(case.frame), time.perf_counter() - t0


def _cell(truth, runs, cache, name) -> list:
    """A cell (n 1.37, nucleus 1.39, in water) imaged by the same instrument, reconstructed with each
    optics: its Δn's correlation with the truth blurred to the resolution, its integrated Δn and peak
    over the truth's, and its depth error (docs/validation.md)."""
    case = val.simulate_case(f"{name}-cell", ph.cell(), truth, cache_dir=cache, source_step=4)
    rows = []
    for how, res, _ in _reconstructed(case, runs):
        m = vt.truth_metrics(res, case.phantom, MEDIUM, CELL_RESOLUTION_UM)
        peak = float(np.max(res.delta_n)) / float(np.max(vt.truth_volume(case.phantom, res, MEDIUM)))
        rows.append({"optics": how, **m, "peak_ratio": peak})
        print(json.dumps(rows[-1], default=float), flush=True)
    return rows


def _pmma(truth, runs, cache, name) -> list:
    """The paper's PMMA bead (13 µm, n 1.49 in oil; 4.4 rad) on a frame of its own, imaged by the
    same instrument and reconstructed with each optics, by `tv` and by `multislice`: integrated Δn
    over its disk and peak Δn over the truth's, and its centroid's depth error (docs/validation.md)."""
    bead = ph.pmma_bead()
    case = val.simulate_case(f"{name}-pmma13", bead, truth, cache_dir=cache, source_step=4)
    rows = []
    for method in ("tv", "multislice"):
        for how, res, seconds in _reconstructed(case, runs, method):
            m = vt.bead_metrics(res, bead, OIL)
            rows.append(
                {
                    "method": method,
                    "optics": how,
                    "mass_ratio": mass_and_tail(res, bead, OIL)["integrated"],
                    "peak_ratio": m["dn_peak"] / m["dn_true"],
                    "ri_centre": m["ri_centre"],
                    "depth_error_um": m["centroid_um"][2],
                    "seconds": seconds,
                }
            )
            print(json.dumps(rows[-1], default=float), flush=True)
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cache", default=None, help="folder for the simulated frames")
    p.add_argument("--fitted", default=None, help="a calibration fitted before (skips the fit)")
    p.add_argument(
        "--condenser", action="store_true", help="the condenser also at NA 0.26 and 0.01 NA off axis (optics: 0.25)"
    )
    p.add_argument("--only", choices=sorted(ALONE), help="one imperfection alone instead")
    p.add_argument("--cell", action="store_true", help="also a cell imaged by the same instrument")
    p.add_argument("--pmma", action="store_true", help="in oil: fitted to PMMA beads, the 13 µm PMMA bead measured")
    p.add_argument("--bead-ri", action="store_true", help="the beads' index given to the fit (as --pmma does)")
    args = p.parse_args()
    medium, beads = (OIL, PMMA_BEADS) if args.pmma else (MEDIUM, BEADS)
    nominal = val.paper_optics(0.25).replace(medium_index=medium)
    lenslets = Grid.nominal(nominal).lenslets(nominal)
    if args.only:
        truth, name = ALONE[args.only](nominal, lenslets), f"pf1-{args.only}"
    else:
        terms = tuple(LensletTerms(row=ln.row, col=ln.col, defocus_waves=DEFOCUS) for ln in lenslets)
        offset = (0.01, 0.0) if args.condenser or args.pmma else (0.0, 0.0)
        ab = Aberrations(objective_zernike_waves=(0.0,) * 10 + (SPHERICAL,), lenslets=terms, condenser_offset_na=offset)
        truth = nominal.replace(aberrations=ab, condenser_na=0.26 if args.condenser or args.pmma else 0.25)
        name = "pf-two-pmma" if args.pmma else "pf-two-condenser" if args.condenser else "pf-two"
    case = val.simulate_case(name, ph.Spheres(beads, medium_index=medium), truth, cache_dir=args.cache, source_step=4)
    cal = calibrate(case.white, nominal)
    seconds = None
    if args.fitted:
        fitted = Calibration.from_json(args.fitted)
    else:
        t0 = time.perf_counter()
        cfg = val.run_config(nominal, z=Z_UM, dz=1.0)
        known = PMMA_RI if args.pmma else float(np.real(beads[0].n)) if args.bead_ri else None
        fit = fit_optics(cal, case.flat, nominal, case.white, beads=BeadFrame(cfg, case.frame, known, name))
        seconds = time.perf_counter() - t0
        print("\n".join(fit.report()), flush=True)
        fitted = fit.calibration
        if args.cache:
            fitted.to_json(Path(args.cache) / f"{name}-fitted.json")  # for --fitted
    runs = {
        "nominal optics": (nominal, cal),
        "pupil fitted to the frame": (nominal, fitted),
        "true optics": (truth, dataclasses.replace(cal, optics=truth)),
    }
    out = {"fit_seconds": seconds, "fitted": fitted.optics_fit.get("pupil"), "rows": []}
    for how, res, _ in _reconstructed(case, runs):
        m = masses_and_false(res, beads, medium)
        row = {"optics": how, "masses": m["masses"], "centroids_z_um": m["centroids_z_um"], "false": m["false"]}
        out["rows"].append(row)
        print(json.dumps(row, default=float), flush=True)
    if args.cell:
        out["cell"] = _cell(truth, runs, args.cache, name)
    if args.pmma:
        out["pmma"] = _pmma(truth, runs, args.cache, name)
    out["bead_ri"] = known if not args.fitted else None
    stem = name.replace("pf-two", "pupil_fit_validation").replace("pf1", "pupil_fit_validation")
    (HERE / f"{stem}{'-ri' if args.bead_ri else ''}.json").write_text(json.dumps(out, indent=1, default=float))
    print("\n| optics | integrated Δn / true (z −10, +15 µm) | centroid depth error (µm) | false Δn |")
    print("| --- | --- | --- | --- |")
    for r in out["rows"]:
        masses = " / ".join(f"{v:.2f}" for v in r["masses"])
        depths = " / ".join(f"{v:+.1f}" for v in r["centroids_z_um"])
        print(f"| {r['optics']} | {masses} | {depths} | {r['false']:.2f} |")


if __name__ == "__main__":
    main()
