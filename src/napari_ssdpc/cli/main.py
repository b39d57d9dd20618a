"""The ``ssdpc`` command line tool.

Bad input ends with one line ``ssdpc: error: ...`` that names the fix, and exit code 2;
never a traceback. Progress bars go to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from napari_ssdpc import __version__
from napari_ssdpc.cli.options import add_reconstruction_options, run_config
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.reconstruction import outputs

PHANTOMS = ("bead", "two-beads", "cell", "bars", "moving")


def _optics(path):
    from napari_ssdpc.settings.optics import Optics

    return Optics.paper() if path is None else Optics.from_yaml(path)


def _check_output(path):
    path = Path(path)
    if not path.parent.exists():
        raise SsdpcError(f"output folder does not exist: {path.parent} (create it first)")
    return path


# ----------------------------------------------------------------------- commands
def cmd_design(args):
    from napari_ssdpc.physics.design import design, design_table

    optics = _optics(args.optics)
    if args.json:
        print(json.dumps(design(optics), indent=2))
    else:
        print(design_table(optics))


def cmd_calibrate(args):
    from napari_ssdpc.calibration.calibrate import calibrate, overlay_png
    from napari_ssdpc.io.frames import read_frame

    optics = _optics(args.optics)
    frame = read_frame(args.frame, allow_series=False)
    out = _check_output(args.output)
    cal = calibrate(frame, optics)
    cal.to_json(out)
    png = out.with_suffix(".png")
    overlay_png(frame, cal, png)
    g = cal.grid
    print(
        f"optical axis (x, y) = ({g.axis_px[0]:.2f}, {g.axis_px[1]:.2f}) px, pitch {g.pitch_px:.3f} px, "
        f"rotation {g.rotation_deg:+.3f} deg, {len(cal.lenslets)} lenslets"
    )
    print(f"wrote {out} and {png}")


def make_phantom(name, optics, *, n_frames=20):
    """Phantom (a list of phantoms for 'moving') and the optics with the phantom's medium."""
    from napari_ssdpc.simulation import phantoms

    makers = {
        "bead": phantoms.pmma_bead,
        "two-beads": phantoms.two_beads,
        "cell": phantoms.cell,
        "bars": phantoms.bar_target,
        "moving": lambda: phantoms.moving_sample(n_frames),
    }
    if name not in makers:
        raise SsdpcError(f"unknown phantom '{name}'; choose one of {', '.join(PHANTOMS)}")
    ph = makers[name]()
    first = ph[0] if isinstance(ph, list) else ph
    if first.medium_index is not None:
        optics = optics.replace(medium_index=float(first.medium_index))
    return ph, optics


def cmd_simulate(args):
    from napari_ssdpc.io.frames import write_tiff
    from napari_ssdpc.physics.lattice import Grid
    from napari_ssdpc.progress import tqdm_callback
    from napari_ssdpc.simulation import simulate as sim

    optics = _optics(args.optics)
    out = _check_output(args.output)
    phantom, optics = make_phantom(args.phantom, optics, n_frames=args.frames)
    grid = Grid.nominal(optics, axis_offset_px=args.offset, rotation_deg=args.rotation)
    rng = np.random.default_rng(args.seed)
    phantoms = phantom if isinstance(phantom, list) else [phantom]
    frames = []
    for i, ph in enumerate(phantoms):
        with tqdm_callback(f"frame {i + 1}/{len(phantoms)}") as cb:
            frames.append(sim.simulate(ph, optics, grid=grid, rng=rng, progress=cb).frame)
    write_tiff(out, np.stack(frames) if len(frames) > 1 else frames[0])
    print(f"wrote {out} {frames[0].shape} x {len(frames)} frame(s)")
    if args.flat:
        write_tiff(args.flat, sim.flat_frame(optics, grid=grid, rng=rng))
        print(f"wrote flat frame {args.flat}")
    if args.white:
        write_tiff(args.white, sim.white_frame(optics, grid=grid, rng=rng))
        print(f"wrote white frame {args.white}")


def _output_paths(out: Path, names):
    """OME-TIFF: RI in OUT.ome.tif, the others beside it as OUT_<name>.ome.tif."""
    stem = out.name[: -len(".ome.tif")] if out.name.endswith(".ome.tif") else out.stem
    return {
        n: out if n == "ri" else out.with_name(f"{stem}{outputs.QUANTITIES[n].file_suffix()}.ome.tif") for n in names
    }


def cmd_reconstruct(args):
    from napari_ssdpc.calibration.calibrate import Calibration
    from napari_ssdpc.io.frames import read_frame, write_ome_tiff
    from napari_ssdpc.io.series import FrameSource, Recipe
    from napari_ssdpc.progress import tqdm_callback

    out = _check_output(args.output)
    is_zarr = out.suffix == ".zarr"
    if not (is_zarr or out.name.endswith((".tif", ".tiff"))):
        raise SsdpcError(f"output {out.name}: give a .ome.tif (one frame) or a .zarr (time series) path")
    save = outputs.parse_save(args.save)
    distributed = args.workers is not None or args.scheduler is not None
    if distributed and not is_zarr:
        raise SsdpcError("--workers/--scheduler spread the frames of a time series; write it to OME-Zarr (-o OUT.zarr)")
    cal = Calibration.from_json(args.calibration)
    if args.optics is not None:
        optics = _optics(args.optics)
    elif args.config is None:
        optics = cal.optics
    else:
        optics = None  # the configuration's
    cfg = run_config(args, optics)
    optics = cfg.optics
    source = FrameSource(args.raw) if is_zarr else None  # a series streams, frame by frame
    frames = None if is_zarr else read_frame(args.raw)
    if frames is not None and frames.ndim == 3 and len(frames) > 1:
        raise SsdpcError(f"{args.raw} holds {len(frames)} frames; write a time series to OME-Zarr (-o OUT.zarr)")
    flat = read_frame(args.flat, allow_series=False) if args.flat else None
    recipe = Recipe(
        optics,
        cal,
        dict(settings=cfg.reconstruction, stacks=any(outputs.QUANTITIES[s].needs_stacks for s in save)),
        flat,
    )
    meta = {
        "software": f"napari-ssdpc {__version__}",
        "optics": optics.to_dict(),
        "calibration": {k: v for k, v in cal.to_dict().items() if k != "lenslets"},
    }
    rec = None
    if not distributed:
        with tqdm_callback("building operators", unit="plane") as cb:
            rec = recipe.build(progress=cb)
        meta["settings"] = rec.settings()
    if is_zarr:
        _reconstruct_series(source, recipe, rec, out, save, meta, args)
        return
    frame = frames if frames.ndim == 2 else frames[0]
    with tqdm_callback("reconstructing", unit="iteration") as cb:
        result = rec.reconstruct(frame, progress=cb)
    images = outputs.images(result, save)
    paths = _output_paths(out, images)
    for name, (data, axes, what) in images.items():
        write_ome_tiff(
            paths[name],
            data,
            axes=axes,
            voxel_um=result.voxel_um,
            description={**meta, "quantity": what, "z_um": result.z_um.tolist()},
        )
    print(f"wrote {', '.join(str(p) for p in paths.values())}")
    _print_summary(result)


def _reconstruct_series(source, recipe, rec, out, save, meta, args):
    """Frames streamed into (t, z, y, x) OME-Zarr images, one chunk per frame; resumable; on a
    Dask cluster with --workers/--scheduler (core/series.py)."""
    from napari_ssdpc.io.series import reconstruct_series

    report = reconstruct_series(
        source, out, recipe, save=save, meta=meta, workers=args.workers, scheduler=args.scheduler, rec=rec
    )
    names = ", ".join(["ri", *save])
    if report.written == 0:
        print(f"{out}: all {report.frames} frames were already written ({names})")
        return
    print(
        f"wrote {out} ({report.written} of {report.frames} frames, {report.skipped} done before: {names}; "
        f"{report.frames_per_second:.2f} frames/s)"
    )


def _print_summary(result):
    dn = result.delta_n
    print(
        f"volume {dn.shape} (z, y, x), voxel {result.voxel_um[0]:g} x {result.voxel_um[1]:.4f} x "
        f"{result.voxel_um[2]:.4f} µm; delta n from {dn.min():+.4f} to {dn.max():+.4f}"
    )


def cmd_bench(args):
    from napari_ssdpc.validation.bench import format_report, run_bench

    report = run_bench(
        quick=args.quick,
        device=args.device,
        cache_dir=args.cache,
        reference=not args.no_reference,
        log=None if args.json else (lambda m: print(m, file=sys.stderr, flush=True)),
    )
    print(json.dumps(report, indent=2) if args.json else format_report(report))


def cmd_demo(args):
    from napari_ssdpc.validation.demo import run_demo

    run_demo(Path(args.output), optics=None if args.optics is None else _optics(args.optics), seed=args.seed)


# ------------------------------------------------------------------------- parser
def build_parser():
    p = argparse.ArgumentParser(
        prog="ssdpc",
        description="Single-shot 3D quantitative phase imaging with a Fourier light-field microscope (ssDPC).",
    )
    p.add_argument("--version", action="version", version=f"napari-ssdpc {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    optics_help = "optics YAML (schema of docs/paper-optics.yaml); default: the paper's optics"

    s = sub.add_parser("design", help="print the design numbers of an optics file (paper Eqs. 8-14)")
    s.add_argument("--optics", help=optics_help)
    s.add_argument("--json", action="store_true", help="print JSON instead of a table")
    s.set_defaults(func=cmd_design)

    s = sub.add_parser("calibrate", help="detect the lenslet grid on a white (condenser fully open) frame")
    s.add_argument("frame", help="white frame TIFF")
    s.add_argument("--optics", help=optics_help)
    s.add_argument("-o", "--output", required=True, help="calibration JSON to write (a PNG overlay goes beside it)")
    s.set_defaults(func=cmd_calibrate)

    s = sub.add_parser("simulate", help="simulate a raw light-field frame of a phantom")
    s.add_argument("phantom", choices=PHANTOMS)
    s.add_argument("--optics", help=optics_help)
    s.add_argument("-o", "--output", required=True, help="frame TIFF to write")
    s.add_argument("--flat", help="also write the flat frame (same condenser NA) here")
    s.add_argument("--white", help="also write the white frame (condenser fully open) here")
    s.add_argument(
        "--offset",
        type=float,
        nargs=2,
        default=(0.0, 0.0),
        metavar=("DX", "DY"),
        help="optical axis offset from the lattice vertex, px",
    )
    s.add_argument("--rotation", type=float, default=0.0, help="MLA rotation on the sensor, degrees")
    s.add_argument("--frames", type=int, default=20, help="frames of the 'moving' time series")
    s.add_argument("--seed", type=int, default=0, help="random seed of the camera noise")
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("reconstruct", help="reconstruct the 3D refractive index of a raw frame or time series")
    s.add_argument("raw", help="raw light-field frame or (t, y, x) series, TIFF/OME-TIFF")
    s.add_argument("--optics", help="optics YAML; default: the optics stored in the calibration")
    s.add_argument("--calibration", required=True, help="calibration JSON from `ssdpc calibrate`")
    s.add_argument("--flat", help="flat frame (no sample, same condenser NA) for flat-fielding")
    add_reconstruction_options(s)
    s.add_argument("--save", help=f"extra outputs, comma separated: {','.join(outputs.SAVE_CHOICES)}")
    s.add_argument(
        "-o", "--output", required=True, help="OUT.ome.tif (one frame) or OUT.zarr (time series; a rerun resumes it)"
    )
    s.add_argument("--workers", type=int, help="spread the frames of a series over a local Dask cluster of N workers")
    s.add_argument("--scheduler", help="spread the frames over an existing Dask cluster (tcp://host:8786)")
    s.set_defaults(func=cmd_reconstruct)

    s = sub.add_parser("bench", help="time the reconstruction (fast path vs reference path, memory, frames/s)")
    s.add_argument("--quick", action="store_true", help="a small case (fewer planes and iterations) in about a minute")
    s.add_argument("--json", action="store_true", help="print JSON instead of tables")
    s.add_argument("--device", choices=("cpu", "gpu"), default="cpu", help="device of the fast path")
    s.add_argument("--cache", help="folder for the simulated frames (default ~/.cache/napari-ssdpc/bench)")
    s.add_argument("--no-reference", action="store_true", help="skip the reference path")
    s.set_defaults(func=cmd_bench)

    s = sub.add_parser("demo", help="simulate the paper's PMMA bead and process it end to end")
    s.add_argument("-o", "--output", default="ssdpc-demo", help="output folder (default ./ssdpc-demo)")
    s.add_argument("--optics", help=optics_help)
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=cmd_demo)
    return p


def _warning_line(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(f"ssdpc: warning: {message}\n")


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    warnings.showwarning = _warning_line
    warnings.simplefilter("always", SsdpcWarning)
    try:
        args.func(args)
    except SsdpcError as e:
        sys.stderr.write(f"ssdpc: error: {e}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("ssdpc: interrupted\n")
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
