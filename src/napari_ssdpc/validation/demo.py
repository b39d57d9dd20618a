"""``ssdpc demo``: simulate the paper's PMMA bead, calibrate on the simulated white frame,
flat-field with the simulated flat frame, reconstruct, refine with the multislice model, and save
the RI volumes and figures."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from napari_ssdpc.calibration import calibrate, overlay_png
from napari_ssdpc.io.frames import write_ome_tiff, write_tiffs
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.progress import tqdm_callback
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation import phantoms
from napari_ssdpc.simulation.sample_free import flat_frame, white_frame
from napari_ssdpc.simulation.simulate import simulate
from napari_ssdpc.validation.cases import VALIDATION_NA, run_config
from napari_ssdpc.validation.figures import bead_figure, comparison_figure, solver_figure
from napari_ssdpc.validation.mass import mass_and_tail
from napari_ssdpc.validation.truth import bead_metrics

# What the demo writes into its folder (each file atomically; the three frames as one set).
DEMO_FILES = (
    "bead.tif", "flat.tif", "white.tif", "calibration.json", "calibration.png", "ri.ome.tif",
    "summary.png", "solver.png",
)  # fmt: skip
# ... and with ``refine``: the multislice refinement beside the first-order answer.
REFINE_FILES = ("ri_multislice.ome.tif", "refined.png")


#: The demo's z range, µm: the 13 µm bead at z 0 with room for its first-order tails (the refinement's
#: model covers every plane, so a range that fits the sample keeps it quick).
DEMO_Z_UM = (-30.0, 30.0)


def run_demo(
    out: Path, optics: Optics | None = None, seed: int = 0, z=DEMO_Z_UM, dz: float = 1.0, refine: bool = True
) -> dict:
    """``ssdpc demo``: simulate the PMMA bead, calibrate, reconstruct, write and summarise.

    Parameters
    ----------
    out : Path
        Folder for the frames, calibration, RI volume and summary figure.
    optics : Optics, optional
        Default the paper's at condenser NA 0.3; the medium becomes the bead's oil (1.518).
    seed : int
        Seed of the camera noise.
    z : (float, float)
        z range, µm.
    dz : float
        Plane spacing, µm.
    refine : bool
        Also refine the answer with the multislice model (``method: multislice``, about 7 minutes
        more): ``ri_multislice.ome.tif`` and ``refined.png``, both methods side by side.

    Returns
    -------
    dict
        ``calibration`` (Calibration), ``result`` (Result), ``metrics`` (of
        :func:`~napari_ssdpc.validation.truth.bead_metrics`), ``simulation_s`` and
        ``reconstruction_s`` (s); with ``refine`` also ``refined`` (Result), ``refined_metrics``
        and ``refine_s`` (s).
    """
    if optics is None:
        # The paper does not state its condenser NA; 0.3 (sigma 0.75) gives the best 3D phase
        # with this MLA (docs/validation.md, condenser-NA sweep).
        optics = Optics.paper().replace(condenser_na=VALIDATION_NA)
        print(f"paper optics with condenser NA {VALIDATION_NA} (see docs/validation.md)")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    bead = phantoms.pmma_bead()
    optics = optics.replace(medium_index=bead.medium_index)
    rng = np.random.default_rng(seed)
    # A realistic instrument: the optical axis a little off the lattice vertex, a small MLA rotation.
    grid = Grid.nominal(optics, axis_offset_px=(7.3, -4.1), rotation_deg=0.6)
    t0 = time.perf_counter()
    with tqdm_callback("simulating the PMMA bead", unit="source point") as cb:
        frame = simulate(bead, optics, grid=grid, rng=rng, progress=cb).frame
    with tqdm_callback("simulating the flat frame", unit="source point") as cb:
        flat = flat_frame(optics, grid=grid, rng=rng, progress=cb)
    print("simulating the white frame (condenser open)", flush=True)
    white = white_frame(optics, grid=grid, rng=rng)
    t_sim = time.perf_counter() - t0
    write_tiffs({out / "bead.tif": frame, out / "flat.tif": flat, out / "white.tif": white})
    print(f"simulated bead, flat and white frames in {t_sim:.0f} s")

    cal = calibrate(white, optics)
    cal.to_json(out / "calibration.json")
    overlay_png(white, cal, out / "calibration.png")
    err = float(np.hypot(*(np.asarray(cal.grid.axis_px) - np.asarray(grid.axis_px))))
    print(
        f"calibration: axis ({cal.grid.axis_px[0]:.2f}, {cal.grid.axis_px[1]:.2f}) px (error {err:.3f} px), "
        f"pitch {cal.grid.pitch_px:.3f} px, rotation {cal.grid.rotation_deg:+.3f} deg"
    )

    t1 = time.perf_counter()
    with tqdm_callback("building operators", unit="plane") as cb:
        rec = Reconstructor(run_config(optics, z=z, dz=dz), cal, flat=flat, progress=cb)
    result = rec.reconstruct(frame)
    t_rec = time.perf_counter() - t1
    _write_ri(out / "ri.ome.tif", result, optics)
    m = bead_metrics(result, bead, optics.medium_index)
    fig = bead_figure(
        result,
        bead,
        optics.medium_index,
        out / "summary.png",
        f"ssDPC demo: 13 µm PMMA bead (n 1.49 in 1.518), condenser NA {optics.condenser_na:g}, "
        f"method {rec.method.name}",
    )
    print(f"reconstructed {result.ri.shape} (z, y, x) in {t_rec:.0f} s (operators {rec.build_seconds:.0f} s)")
    _print_bead(rec.method.name, result, bead, optics, m)
    st = result.settings
    if rec.method.name == "tv":
        print(
            f"TV solve: {st['tv_iterations_run']} iterations, sign {st['tv_sign']}, noise {st['tv_noise']:.3g}, "
            f"residual / noise {st['tv_residual_over_noise']:.1f}"
        )
    solver = solver_figure(result, out / "solver.png", f"how the '{rec.method.name}' solver ran")
    print(f"wrote {out / 'ri.ome.tif'}, {fig} and {solver}")
    done = {"calibration": cal, "result": result, "metrics": m, "simulation_s": t_sim, "reconstruction_s": t_rec}
    if refine:
        done.update(_refine(out, frame, rec, optics, bead, result, z, dz))
    return done


def _refine(out: Path, frame, rec: Reconstructor, optics: Optics, bead, first, z, dz) -> dict:
    """The multislice refinement of the demo's frame, written and drawn beside the first answer:
    the same Reconstructor refines its own 'tv' answer (no operators rebuilt, no second 'tv' solve)."""
    t0 = time.perf_counter()
    with tqdm_callback("multislice refinement", unit="iteration") as cb:
        if not rec.adopt(run_config(optics, z=z, dz=dz, method="multislice")):
            raise RuntimeError("the demo's reconstructor cannot take the multislice refinement")
        refined = rec.reconstruct(frame, progress=cb)
    seconds = time.perf_counter() - t0
    _write_ri(out / "ri_multislice.ome.tif", refined, optics)
    m = bead_metrics(refined, bead, optics.medium_index)
    st = refined.settings
    print(
        f"multislice: {st['multislice_iterations_run']} iterations in {seconds:.0f} s, "
        f"residual / noise {st['multislice_residual_over_noise']:.1f} (first-order model: "
        f"{first.settings.get('tv_residual_over_noise', float('nan')):.0f})"
    )
    _print_bead("multislice", refined, bead, optics, m)
    fig = comparison_figure(
        {first.settings.get("method", "tv"): first, "multislice": refined},
        bead,
        optics.medium_index,
        out / "refined.png",
        "13 µm PMMA bead: the first-order answer and its multislice refinement",
    )
    print(f"wrote {out / 'ri_multislice.ome.tif'} and {fig}")
    return {"refined": refined, "refined_metrics": m, "refine_s": seconds}


def _write_ri(path: Path, result, optics: Optics) -> None:
    write_ome_tiff(
        path,
        result.ri,
        axes="ZYX",
        voxel_um=result.voxel_um,
        description={"quantity": "refractive index", "settings": result.settings, "optics": optics.to_dict()},
    )


def _print_bead(method: str, result, bead, optics: Optics, m: dict) -> None:
    """One line per method: RI at the centre, centroid, size, and how much of the bead it keeps."""
    cx, cy, cz = m["centroid_um"]
    kept = mass_and_tail(result, bead, optics.medium_index)
    print(
        f"{method}: RI at the centre {m['ri_centre']:.4f} (true 1.49), centroid ({cx:+.2f}, {cy:+.2f}, {cz:+.2f}) µm, "
        f"FWHM lateral {m['fwhm_x_um']:.1f} µm, axial {m['fwhm_z_um']:.1f} µm; integrated Δn "
        f"{kept['integrated']:.2f} x the truth, tail along z {kept['tail']:.2f}"
    )
