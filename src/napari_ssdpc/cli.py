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
    """Phantom (or list of phantoms for 'moving') and the optics to simulate it with."""
    from .core import simulate as sim

    if name == "bead":
        return sim.pmma_bead(), optics
    if name == "two-beads":
        return sim.two_beads(), optics
    if name == "cell":
        return sim.cell(), optics.replace(medium_index=1.33)
    if name == "bars":
        return sim.bar_target(), optics
    if name == "moving":
        return sim.moving_sample(n_frames), optics.replace(medium_index=1.33)
    raise SsdpcError(f"unknown phantom '{name}'; choose one of {', '.join(PHANTOMS)}")


def cmd_simulate(args):
    import numpy as np

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


def cmd_demo(args):
    from .demo import run_demo

    run_demo(Path(args.output), optics=_optics(args.optics), seed=args.seed)


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
