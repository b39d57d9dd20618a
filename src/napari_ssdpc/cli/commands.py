"""The ``ssdpc`` subcommands. Each checks every input and output before it computes or writes.

Outputs are compared with the inputs (:func:`napari_ssdpc.io.paths.check_outputs`) first; sets
of files are written as one unit; results are checked (:mod:`.checks`) before they are written.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from napari_ssdpc.cli.follow import follow_recording, followed, report_series
from napari_ssdpc.cli.options import config_from_args, optics_file, outputs_from_args
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.paths import check_outputs, is_ours, writable_folder
from napari_ssdpc.settings.outputs import QUANTITIES

__all__ = [
    "cmd_resign",
    "PHANTOMS",
    "cmd_bench",
    "cmd_calibrate",
    "cmd_demo",
    "cmd_design",
    "cmd_reconstruct",
    "cmd_simulate",
    "make_phantom",
    "output_paths",
]

PHANTOMS = ("bead", "two-beads", "cell", "bars", "moving")


def cmd_design(args):
    """Print the design calculator's table (or JSON) for the optics.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc design` (see ``ssdpc design --help``).
    """
    from napari_ssdpc.physics.design import design, design_table

    optics = optics_file(args.optics)
    print(json.dumps(design(optics), indent=2) if args.json else design_table(optics))


def cmd_calibrate(args):
    """Calibrate the lattice from a white (or sample) frame; write the JSON and the overlay PNG.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc calibrate` (see ``ssdpc calibrate --help``).
    """
    from napari_ssdpc.calibration import calibrate, overlay_png
    from napari_ssdpc.io.frames import read_frame

    out = Path(args.output)
    png = out.with_suffix(".png")
    check_outputs(
        {"calibration": out, "overlay": png},
        {"white frame": args.frame, "optics file": args.optics},
        overwrite=args.overwrite,
        replaceable=lambda p: is_ours(p) or (p.suffix == ".png" and _is_calibration(out)),  # older overlays: unstamped
    )
    optics = optics_file(args.optics)
    frame = read_frame(args.frame, allow_series=False, name="white frame")
    cal = calibrate(frame, optics, axis=args.axis)
    overlay_png(frame, cal, png)  # the overlay first: a failure leaves no new JSON without its overlay
    cal.to_json(out)
    g = cal.grid
    print(
        f"optical axis (x, y) = ({g.axis_px[0]:.2f}, {g.axis_px[1]:.2f}) px, pitch {g.pitch_px:.3f} px, "
        f"rotation {g.rotation_deg:+.3f} deg, {len(cal.lenslets)} lenslets"
    )
    print(cal.optics.aberrations.summary())
    if cal.rim_defocus_waves is not None:
        print(f"views' focus from the EI rims: |d| {cal.rim_defocus_waves:.2f} waves at the sub-aperture's edge")
    print(f"wrote {out} and {png}")


def _can_create(folder: Path) -> bool:
    """Whether ``folder`` exists and is writable, or can be made in its nearest existing parent."""
    while not folder.exists():
        folder = folder.parent
    return folder.is_dir() and os.access(folder, os.W_OK | os.X_OK)


def _check_seed(seed: int) -> None:
    if seed < 0:
        raise SsdpcError(f"--seed {seed}: give a seed >= 0")


def _is_calibration(path: Path) -> bool:
    return path.is_file() and is_ours(path)


def make_phantom(name, optics, *, n_frames=20):
    """Phantom (a list of phantoms for 'moving') and the optics with the phantom's medium.

    Parameters
    ----------
    name : str
        One of :data:`PHANTOMS`.
    optics : Optics
    n_frames : int
        Frames of 'moving'.

    Returns
    -------
    tuple
        (phantom or list of phantoms, Optics)
    """
    from napari_ssdpc.simulation import moving, phantoms

    makers = {
        "bead": phantoms.pmma_bead,
        "two-beads": phantoms.two_beads,
        "cell": phantoms.cell,
        "bars": phantoms.bar_target,
        "moving": lambda: moving.moving_sample(n_frames),
    }
    if name not in makers:
        raise SsdpcError(f"unknown phantom '{name}'; choose one of {', '.join(PHANTOMS)}")
    ph = makers[name]()
    return ph, phantoms.optics_for(ph, optics)


def _check_simulate_numbers(args, optics):
    dx, dy = args.offset
    if not (math.isfinite(dx) and math.isfinite(dy)):
        raise SsdpcError(f"--offset {dx:g} {dy:g}: give finite numbers of pixels")
    reach = 0.5 * float(optics.pitch_px)
    if abs(dx) > reach or abs(dy) > reach:
        raise SsdpcError(
            f"--offset {dx:g} {dy:g} px: the axis offset from the lattice vertex is at most half a pitch "
            f"(±{reach:.1f} px); give a smaller offset"
        )
    if not math.isfinite(args.rotation) or abs(args.rotation) > 45:
        raise SsdpcError(f"--rotation {args.rotation:g}: give a finite angle between -45 and 45 degrees")
    _check_seed(args.seed)
    if args.frames < 1 or args.frames > 10000:
        raise SsdpcError(f"--frames {args.frames}: give 1 to 10000 frames")


def cmd_resign(args):
    """Accept a deliberately edited calibration file: check it and write its checksum anew.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc resign-calibration`.
    """
    from napari_ssdpc.calibration.result import Calibration

    cal = Calibration.from_json(args.calibration, verify=False)  # every value is still validated
    cal.to_json(args.calibration)
    print(f"{args.calibration}: signed anew; its edits are now its content")


def cmd_simulate(args):
    """Simulate raw frames of a phantom (and the flat and white frames) with the multislice model.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc simulate` (see ``ssdpc simulate --help``).
    """
    from napari_ssdpc.io.frames import write_tiffs
    from napari_ssdpc.physics.lattice import Grid
    from napari_ssdpc.progress import tqdm_callback
    from napari_ssdpc.simulation.sample_free import flat_frame, white_frame
    from napari_ssdpc.simulation.simulate import simulate

    wanted = {"frame": args.output, "flat frame": args.flat, "white frame": args.white}
    outs = check_outputs({k: v for k, v in wanted.items() if v}, {"optics file": args.optics}, overwrite=args.overwrite)
    optics = optics_file(args.optics)
    _check_simulate_numbers(args, optics)
    given = optics.medium_index
    phantom, optics = make_phantom(args.phantom, optics, n_frames=args.frames)
    if optics.medium_index != given:  # the phantom's own medium: the calibration must say the same
        print(
            f"note: the '{args.phantom}' phantom lies in a medium of index {optics.medium_index:g}, not the optics' "
            f"{given:g}: simulated with {optics.medium_index:g}; calibrate with optics whose medium_index is "
            f"{optics.medium_index:g}, or every RI is labelled {given - optics.medium_index:+.3f} off",
            file=sys.stderr,
        )
    grid = Grid.nominal(optics, axis_offset_px=tuple(args.offset), rotation_deg=args.rotation)
    rng = np.random.default_rng(args.seed)
    phantoms = phantom if isinstance(phantom, list) else [phantom]
    frames = []
    for i, ph in enumerate(phantoms):
        with tqdm_callback(f"frame {i + 1}/{len(phantoms)}") as cb:
            frames.append(simulate(ph, optics, grid=grid, rng=rng, progress=cb).frame)
    data = {outs["frame"]: np.stack(frames) if len(frames) > 1 else frames[0]}
    if "flat frame" in outs:
        data[outs["flat frame"]] = flat_frame(optics, grid=grid, rng=rng)
    if "white frame" in outs:
        data[outs["white frame"]] = white_frame(optics, grid=grid, rng=rng)
    write_tiffs(data)
    print(f"wrote {outs['frame']} {frames[0].shape} x {len(frames)} frame(s)")
    for role in ("flat frame", "white frame"):
        if role in outs:
            print(f"wrote {role} {outs[role]}")


def output_paths(out: Path, names) -> dict:
    """OME-TIFF: RI in OUT.ome.tif, the others beside it as OUT_<name>.ome.tif.

    Parameters
    ----------
    out : Path
        The main output.
    names : iterable of str
        Quantities ('ri' first).

    Returns
    -------
    dict of str to Path
    """
    stem = out.name[: -len(".ome.tif")] if out.name.endswith(".ome.tif") else out.stem
    return {n: out if n == "ri" else out.with_name(f"{stem}{QUANTITIES[n].file_suffix()}.ome.tif") for n in names}


def cmd_reconstruct(args):
    """Reconstruct one frame or a series to RI volumes (OME-TIFF, or a resumable OME-Zarr store).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc reconstruct` (see ``ssdpc reconstruct --help``).
    """
    from napari_ssdpc.calibration.result import Calibration
    from napari_ssdpc.io.frame_source import StoredFrames
    from napari_ssdpc.io.frames import read_frame
    from napari_ssdpc.pipeline.job import Job
    from napari_ssdpc.pipeline.run import Pipeline
    from napari_ssdpc.pipeline.sinks import OmeTiffSink, ZarrSink
    from napari_ssdpc.progress import tqdm_callback

    out = Path(args.output)
    is_zarr = out.suffix == ".zarr"
    inputs = {
        "raw frame": args.raw,
        "calibration": args.calibration,
        "flat frame": args.flat,
        "optics file": args.optics,
        "settings file": args.config,
    }
    # the paths first: --save or the config's outputs may add files beside the output
    paths = output_paths(out, ["ri", *outputs_from_args(args).save])
    check_outputs(
        {("output" if n == "ri" else f"{n} output"): p for n, p in paths.items()},
        inputs,
        overwrite=args.overwrite,
        folders=["output"] if is_zarr else [],
    )
    if not (is_zarr or out.name.endswith((".tif", ".tiff"))):
        raise SsdpcError(f"output {out.name}: give a .ome.tif (one frame) or a .zarr (time series) path")
    distributed = args.workers is not None or args.scheduler is not None
    if distributed and not is_zarr:
        raise SsdpcError("--workers/--scheduler spread the frames of a time series; write it to OME-Zarr (-o OUT.zarr)")
    if getattr(args, "store_digits", None) is not None and not is_zarr:
        raise SsdpcError("--store-digits sets how a series store keeps its values; give -o OUT.zarr, or leave it out")
    follow = getattr(args, "follow", False)
    if follow and (distributed or not is_zarr):
        raise SsdpcError("--follow writes the frames one after the other into a store: give -o OUT.zarr, no --workers")
    if follow and not (math.isfinite(args.idle) and args.idle > 0):
        raise SsdpcError(f"--idle must be a positive number of seconds, got {args.idle}")
    cal = Calibration.from_json(args.calibration)
    cfg = config_from_args(args, None if args.optics is None else optics_file(args.optics), fallback=cal.optics)
    if follow:
        source = followed(args.raw, args.idle)
    else:
        # a series streams, frame by frame
        source = StoredFrames(args.raw if is_zarr else read_frame(args.raw), label=Path(args.raw).name)
    flat = read_frame(args.flat, allow_series=False, name="flat frame") if args.flat else None
    job = Job(cfg, cal, flat)
    meta = job.metadata(Path(args.raw).name)
    sink = ZarrSink(out, cfg.outputs.save, meta) if is_zarr else OmeTiffSink(paths, meta)
    if not is_zarr and len(source) > 1:
        raise SsdpcError(f"{args.raw} holds {len(source)} frames; write a time series to OME-Zarr (-o OUT.zarr)")
    with tqdm_callback("building operators", unit="plane", disable=distributed) as cb:
        pipeline = Pipeline(job, progress=cb, workers=args.workers, scheduler=args.scheduler)
    if follow:
        follow_recording(pipeline, source, sink, out, cfg.outputs.save)
        return
    if is_zarr:
        report_series(pipeline.run(source, sink), out, cfg.outputs.save)
        return
    with tqdm_callback("reconstructing", unit="iteration") as cb:
        pipeline.run(source, sink, iteration_progress=cb, progress=False)
    print(f"wrote {', '.join(str(p) for p in sink.written)}")
    res = sink.result
    dn, voxel = res.delta_n, res.voxel_um
    print(
        f"volume {dn.shape} (z, y, x), voxel {voxel[0]:g} x {voxel[1]:.4f} x {voxel[2]:.4f} µm; "
        f"delta n from {dn.min():+.4f} to {dn.max():+.4f}"
    )


def cmd_bench(args):
    """Run the speed benchmark and print its report.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc bench` (see ``ssdpc bench --help``).
    """
    from napari_ssdpc.validation.bench import default_cache, run_bench
    from napari_ssdpc.validation.bench_report import format_report

    if args.cache is not None:
        cache = Path(args.cache)
        if cache.exists() and not cache.is_dir():
            raise SsdpcError(f"--cache {cache} is a file; give a folder")
        writable_folder(cache if cache.exists() else cache.parent, "--cache folder")
    else:
        cache = default_cache()
        if not _can_create(cache):  # a read-only home: simulate without keeping the frames
            cache = Path(tempfile.mkdtemp(prefix="ssdpc-bench-"))
            print(f"ssdpc: note: {default_cache()} is not writable; simulated frames go to {cache}", file=sys.stderr)
    report = run_bench(
        quick=args.quick,
        device=args.device,
        cache_dir=cache,
        reference=not args.no_reference,
        log=None if args.json else (lambda m: print(m, file=sys.stderr, flush=True)),
    )
    print(json.dumps(report, indent=2) if args.json else format_report(report))


def cmd_demo(args):
    """Simulate, calibrate and reconstruct a bead end to end; write the summary figure.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc demo` (see ``ssdpc demo --help``).
    """
    from napari_ssdpc.validation.demo import DEMO_FILES, REFINE_FILES, run_demo

    _check_seed(args.seed)
    out = Path(args.output)
    check_outputs({"demo folder": out}, {"optics file": args.optics}, folders=["demo folder"])
    if out.exists() and not out.is_dir():
        raise SsdpcError(f"demo folder {out} is a file; give a new folder name")
    if out.is_dir():
        writable_folder(out, "demo folder")
        names = DEMO_FILES + (REFINE_FILES if args.refine else ())
        check_outputs({name: out / name for name in names}, {"optics file": args.optics}, overwrite=args.overwrite)
    run_demo(out, optics=None if args.optics is None else optics_file(args.optics), seed=args.seed, refine=args.refine)
