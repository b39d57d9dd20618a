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

from . import __version__
from .core.errors import SsdpcError, SsdpcWarning

PHANTOMS = ("bead", "two-beads", "cell", "bars", "moving")


def _optics(path):
    from .core.optics import Optics

    return Optics.paper() if path is None else Optics.from_yaml(path)


def _check_output(path):
    path = Path(path)
    if not path.parent.exists():
        raise SsdpcError(f"output folder does not exist: {path.parent} (create it first)")
    return path


# ----------------------------------------------------------------------- commands
def cmd_design(args):
    from .core.optics import design_table

    optics = _optics(args.optics)
    if args.json:
        print(json.dumps(optics.design(), indent=2))
    else:
        print(design_table(optics))


def cmd_calibrate(args):
    from .core.io import read_frame
    from .core.lenslets import calibrate, overlay_png

    optics = _optics(args.optics)
    frame = read_frame(args.frame, allow_series=False)
    out = _check_output(args.output)
    cal = calibrate(frame, optics)
    cal.to_json(out)
    png = out.with_suffix(".png")
    overlay_png(frame, cal, png)
    g = cal.grid
    print(f"optical axis (x, y) = ({g.axis_px[0]:.2f}, {g.axis_px[1]:.2f}) px, pitch {g.pitch_px:.3f} px, "
          f"rotation {g.rotation_deg:+.3f} deg, {len(cal.lenslets)} lenslets")
    print(f"wrote {out} and {png}")


def make_phantom(name, optics, *, n_frames=20):
    """Phantom (a list of phantoms for 'moving') and the optics with the phantom's medium."""
    from .core import phantoms

    makers = {"bead": phantoms.pmma_bead, "two-beads": phantoms.two_beads, "cell": phantoms.cell,
              "bars": phantoms.bar_target, "moving": lambda: phantoms.moving_sample(n_frames)}
    if name not in makers:
        raise SsdpcError(f"unknown phantom '{name}'; choose one of {', '.join(PHANTOMS)}")
    ph = makers[name]()
    first = ph[0] if isinstance(ph, list) else ph
    if first.medium_index is not None:
        optics = optics.replace(medium_index=float(first.medium_index))
    return ph, optics


def cmd_simulate(args):
    from .core import simulate as sim
    from .core.grid import Grid
    from .core.io import write_tiff
    from .core.progress import tqdm_callback

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


SAVE_CHOICES = ("phase", "dpc", "stacks", "absorption", "delta_n")


def _result_images(result, save):
    """{name: (array, axes, description)} of the requested outputs of one frame."""
    out = {"ri": (result.ri, "ZYX", "refractive index")}
    if "delta_n" in save:
        out["delta_n"] = (result.delta_n, "ZYX", "refractive-index difference to the medium")
    if "phase" in save:
        out["phase"] = (result.phase, "ZYX", "phase per slab, rad")
    if "absorption" in save:
        out["absorption"] = (result.absorption, "ZYX", "absorption mu per slab")
    if "dpc" in save:
        out["dpc"] = (np.stack([result.dpc["ud"], result.dpc["lr"]]), "CZYX", "DPC up-down, left-right")
    if "stacks" in save:
        out["stacks"] = (np.stack([result.stacks[h] for h in ("up", "down", "left", "right")]), "CZYX",
                         "RL intensity stacks up, down, left, right")
    return out


def _output_paths(out: Path, names):
    """OME-TIFF: RI in OUT.ome.tif, the others beside it as OUT_<name>.ome.tif."""
    stem = out.name[: -len(".ome.tif")] if out.name.endswith(".ome.tif") else out.stem
    return {n: out if n == "ri" else out.with_name(f"{stem}_{n}.ome.tif") for n in names}


def cmd_reconstruct(args):
    from .core.io import read_frame, write_ome_tiff
    from .core.lenslets import Calibration
    from .core.pipeline import Reconstructor
    from .core.progress import tqdm_callback

    out = _check_output(args.output)
    is_zarr = out.suffix == ".zarr"
    if not (is_zarr or out.name.endswith((".tif", ".tiff"))):
        raise SsdpcError(f"output {out.name}: give a .ome.tif (one frame) or a .zarr (time series) path")
    save = [s.strip() for s in (args.save or "").split(",") if s.strip()]
    bad = [s for s in save if s not in SAVE_CHOICES]
    if bad:
        raise SsdpcError(f"--save {','.join(bad)}: unknown output; choose from {','.join(SAVE_CHOICES)}")
    cal = Calibration.from_json(args.calibration)
    optics = cal.optics if args.optics is None else _optics(args.optics)
    raw = read_frame(args.raw)
    flat = read_frame(args.flat, allow_series=False) if args.flat else None
    frames = raw[None] if raw.ndim == 2 else raw
    if len(frames) > 1 and not is_zarr:
        raise SsdpcError(f"{args.raw} holds {len(frames)} frames; write a time series to OME-Zarr (-o OUT.zarr)")
    z = args.z if args.z is not None else None
    with tqdm_callback("building operators", unit="plane") as cb:
        rec = Reconstructor(optics, cal, z=z, dz=args.dz, iterations=args.iterations, alpha=args.alpha,
                            model=args.model, method=args.method, flat=flat,
                            stacks=bool({"dpc", "stacks", "absorption"} & set(save)),
                            progress=lambda i, n, label="": cb(i, n))
    meta = {"software": f"napari-ssdpc {__version__}", "settings": rec.settings(), "optics": optics.to_dict(),
            "calibration": {k: v for k, v in cal.to_dict().items() if k != "lenslets"}}
    if is_zarr:
        _reconstruct_series(frames, rec, out, save, meta)
        return
    with tqdm_callback("reconstructing", unit="iteration") as cb:
        result = rec.reconstruct(frames[0], progress=lambda i, n, label="": cb(i, n))
    images = _result_images(result, save)
    paths = _output_paths(out, images)
    for name, (data, axes, what) in images.items():
        write_ome_tiff(paths[name], data, axes=axes, voxel_um=result.voxel_um,
                       description={**meta, "quantity": what, "z_um": result.z_um.tolist()})
    print(f"wrote {', '.join(str(p) for p in paths.values())}")
    _print_summary(result)


def _reconstruct_series(frames, rec, out, save, meta):
    """Frame by frame into (t, z, y, x) OME-Zarr images, one chunk per frame."""
    from tqdm.auto import tqdm

    from .core.io import create_ome_zarr

    arrays = {}
    for t, frame in enumerate(tqdm(frames, desc="frames", unit="frame", file=sys.stderr)):
        result = rec.reconstruct(np.asarray(frame))
        for name, (data, axes, what) in _result_images(result, save).items():
            if name not in arrays:
                arrays[name] = create_ome_zarr(out, name, (len(frames),) + data.shape, "T" + axes,
                                               result.voxel_um, attrs={**meta, "quantity": what},
                                               overwrite=True)
            arrays[name][t] = data
    print(f"wrote {out} ({len(frames)} frames: {', '.join(arrays)})")


def _print_summary(result):
    dn = result.delta_n
    print(f"volume {dn.shape} (z, y, x), voxel {result.voxel_um[0]:g} x {result.voxel_um[1]:.4f} x "
          f"{result.voxel_um[2]:.4f} µm; delta n from {dn.min():+.4f} to {dn.max():+.4f}")


def cmd_demo(args):
    from .demo import run_demo

    run_demo(Path(args.output), optics=None if args.optics is None else _optics(args.optics), seed=args.seed)


# ------------------------------------------------------------------------- parser
def build_parser():
    p = argparse.ArgumentParser(prog="ssdpc", description="Single-shot 3D quantitative phase imaging "
                                "with a Fourier light-field microscope (ssDPC).")
    p.add_argument("--version", action="version", version=f"napari-ssdpc {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    optics_help = "optics YAML (schema of shared/paper-optics.yaml); default: the paper's optics"

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
    s.add_argument("--offset", type=float, nargs=2, default=(0.0, 0.0), metavar=("DX", "DY"),
                   help="optical axis offset from the lattice vertex, px")
    s.add_argument("--rotation", type=float, default=0.0, help="MLA rotation on the sensor, degrees")
    s.add_argument("--frames", type=int, default=20, help="frames of the 'moving' time series")
    s.add_argument("--seed", type=int, default=0, help="random seed of the camera noise")
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("reconstruct", help="reconstruct the 3D refractive index of a raw frame or time series")
    s.add_argument("raw", help="raw light-field frame or (t, y, x) series, TIFF/OME-TIFF")
    s.add_argument("--optics", help="optics YAML; default: the optics stored in the calibration")
    s.add_argument("--calibration", required=True, help="calibration JSON from `ssdpc calibrate`")
    s.add_argument("--flat", help="flat frame (no sample, same condenser NA) for flat-fielding")
    s.add_argument("--z", type=float, nargs=2, metavar=("ZMIN", "ZMAX"), help="z range in µm (default -80 80)")
    s.add_argument("--dz", type=float, help="slice spacing in µm (default 1)")
    s.add_argument("--iterations", type=int, help="Richardson-Lucy iterations (default 15)")
    s.add_argument("--alpha", type=float, help="Tikhonov regularisation (default 0.1 for wotf, 0.01 for rl)")
    s.add_argument("--model", choices=("lenslet", "paper"), help="transfer-function model (default lenslet)")
    s.add_argument("--method", choices=("wotf", "rl"), help="phase method (default wotf, see docs/validation.md)")
    s.add_argument("--save", help=f"extra outputs, comma separated: {','.join(SAVE_CHOICES)}")
    s.add_argument("-o", "--output", required=True, help="OUT.ome.tif (one frame) or OUT.zarr (time series)")
    s.set_defaults(func=cmd_reconstruct)

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
