"""``ssdpc fit-optics``: what the user's frames say the instrument is, written into a new calibration.

It fits the condenser (its NA and its centre off the optical axis) to the lenslets' light on a flat
frame, and every reconstruction made with the new calibration uses them; given the white frame, it
measures each view's focus on its EI rims and says when they are blurred (docs/aberrations.md).
"""

from __future__ import annotations

from pathlib import Path

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
        help="fit the condenser's NA and centre to a flat frame; write a calibration with them",
        description="The flat frame's lenslet levels are the overlaps of the condenser disk with each lenslet's "
        "sub-aperture: its NA and its centre are fitted (docs/aberrations.md). Prints each term with its "
        "uncertainty and the misfit before and after; writes a copy of the calibration with the fitted optics.",
    )
    s.add_argument("--calibration", required=True, help="calibration JSON from `ssdpc calibrate`")
    s.add_argument("--flat", required=True, help="flat frame (no sample, the raw frames' condenser NA)")
    s.add_argument(
        "--white",
        help="the white frame the calibration was made on: each view's focus is measured on its EI rims",
    )
    s.add_argument("--optics", help="optics YAML; default: the optics stored in the calibration")
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
    from napari_ssdpc.cli.options import optics_file
    from napari_ssdpc.io.frames import read_frame
    from napari_ssdpc.io.paths import check_outputs, is_ours
    from napari_ssdpc.progress import tqdm_callback
    from napari_ssdpc.reconstruction.optics_fit import fit_optics

    out = Path(args.output)
    check_outputs(
        {"calibration": out},
        {
            "calibration": args.calibration,
            "flat frame": args.flat,
            "white frame": args.white,
            "optics file": args.optics,
        },
        overwrite=args.overwrite,
        replaceable=is_ours,
    )
    cal = Calibration.from_json(args.calibration)
    optics = None if args.optics is None else optics_file(args.optics)
    flat = read_frame(args.flat, allow_series=False, name="flat frame")
    white = None if args.white is None else read_frame(args.white, allow_series=False, name="white frame")
    if white is None:
        fit = fit_optics(cal, flat, optics)
    else:
        with tqdm_callback("measuring the views' focus", unit="defocus") as cb:
            fit = fit_optics(cal, flat, optics, white, progress=cb)
    fit.calibration.to_json(out)
    for line in fit.report():
        print(line)
    print(f"wrote {out}")
