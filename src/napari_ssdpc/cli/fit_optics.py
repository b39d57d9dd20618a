"""``ssdpc fit-optics``: what the user's frames say the instrument is, written into a new calibration.

It fits the condenser (its NA and its centre off the optical axis) to the lenslets' light on a flat
frame, and every reconstruction made with the new calibration uses them; given the white frame, it
measures each view's focus on its EI rims and says when they are blurred; given a frame of beads, it
fits the objective's aberration and every view's defocus (with its sign) to the beads, their centres
and sizes free (docs/aberrations.md).
"""

from __future__ import annotations

from pathlib import Path

from napari_ssdpc.errors import SsdpcError

__all__ = ["add_fit_optics_command", "cmd_fit_optics"]


def add_fit_optics_command(sub) -> None:
    """Add ``fit-optics`` to the subcommands of ``ssdpc``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``ssdpc`` parser.
    """
    s = sub.add_parser(
        "fit-optics",
        help="fit the instrument to its own frames (condenser, views' focus, the objective's aberration); "
        "write a calibration with it",
        description="The flat frame's lenslet levels are the overlaps of the condenser disk with each lenslet's "
        "sub-aperture: its NA and its centre are fitted. A frame of beads (FRAME) gives the objective's "
        "aberration (Zernike astigmatism, coma, spherical) and each view's defocus (docs/aberrations.md). Prints "
        "each term with its uncertainty and the misfit before and after; writes a copy of the calibration with "
        "the fitted optics.",
    )
    s.add_argument(
        "frame", nargs="?", help="raw frame of beads (optional): the objective's aberration and the views' focus"
    )
    s.add_argument("--calibration", required=True, help="calibration JSON from `ssdpc calibrate`")
    s.add_argument("--flat", required=True, help="flat frame (no sample, the raw frames' condenser NA)")
    s.add_argument(
        "--white",
        help="the white frame the calibration was made on: each view's focus is measured on its EI rims",
    )
    s.add_argument("--optics", help="optics YAML; default: the optics stored in the calibration")
    s.add_argument("--bead-ri", type=float, help="the beads' refractive index, when known (held in the fit)")
    s.add_argument("--medium-index", type=float, help="the beads' medium's index (default: the optics')")
    s.add_argument("--z", type=float, nargs=2, metavar=("ZMIN", "ZMAX"), help="z range the beads lie in, µm")
    s.add_argument("-o", "--output", required=True, help="calibration JSON to write, with the fitted optics")
    s.add_argument("--overwrite", action="store_true", help="replace the output whatever it holds")
    s.set_defaults(func=cmd_fit_optics)


def cmd_fit_optics(args) -> None:
    """Fit the condenser to the flat frame and write the calibration with it.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of ``ssdpc fit-optics`` (see ``ssdpc fit-optics --help``).
    """
    from napari_ssdpc.calibration.result import Calibration
    from napari_ssdpc.cli.options import config_from_args, optics_file
    from napari_ssdpc.io.frames import read_frame
    from napari_ssdpc.io.paths import check_outputs, is_ours
    from napari_ssdpc.progress import tqdm_callback
    from napari_ssdpc.reconstruction.optics_fit import BeadFrame, fit_optics

    out = Path(args.output)
    check_outputs(
        {"calibration": out},
        {
            "calibration": args.calibration,
            "flat frame": args.flat,
            "white frame": args.white,
            "optics file": args.optics,
            "bead frame": args.frame,
        },
        overwrite=args.overwrite,
        replaceable=is_ours,
    )
    cal = Calibration.from_json(args.calibration)
    optics = None if args.optics is None else optics_file(args.optics)
    flat = read_frame(args.flat, allow_series=False, name="flat frame")
    white = None if args.white is None else read_frame(args.white, allow_series=False, name="white frame")
    if args.frame is None and (args.bead_ri is not None or args.medium_index is not None or args.z is not None):
        raise SsdpcError("--bead-ri, --medium-index and --z describe a frame of beads: give the frame (FRAME)")
    beads = None
    if args.frame is not None:
        cfg = config_from_args(args, optics, fallback=cal.optics)
        if args.medium_index is not None:
            cfg = cfg.replace(optics=cfg.optics.replace(medium_index=args.medium_index).to_dict())
        frame = read_frame(args.frame, allow_series=False, name="bead frame")
        beads = BeadFrame(cfg, frame, args.bead_ri, Path(args.frame).name)
    with tqdm_callback("fitting the optics", unit="step") as cb:
        fit = fit_optics(cal, flat, optics, white, progress=cb, beads=beads)
    fit.calibration.to_json(out)
    for line in fit.report():
        print(line)
    print(f"wrote {out}")
