"""``ssdpc beads``: every bead of a frame fitted as a sphere (centre, diameter, RI), one line each or JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path

from napari_ssdpc.errors import SsdpcError

__all__ = ["add_beads_command", "bead_line", "cmd_beads"]


def add_beads_command(sub) -> None:
    """Add ``beads`` to the subcommands of ``ssdpc``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``ssdpc`` parser.
    """
    s = sub.add_parser(
        "beads",
        help="fit every bead of a frame as a sphere: centre, diameter and RI (an instrument's first check)",
        description="The beads are the objects of the frame's 'tv' answer; each is fitted as a sphere with the "
        "multislice model of the views (docs/beads.md). One line per bead, or JSON with --json.",
    )
    s.add_argument("raw", help="raw light-field frame (TIFF/OME-TIFF, one frame)")
    s.add_argument("--calibration", required=True, help="calibration JSON from `ssdpc calibrate`")
    s.add_argument("--flat", help="flat frame (no sample, same condenser NA) for flat-fielding")
    s.add_argument("--optics", help="optics YAML; default: the optics stored in the calibration")
    s.add_argument("--medium-index", type=float, help="the immersion medium's index (default: the optics')")
    s.add_argument("--config", help="run configuration YAML (its optics and reconstruction sections)")
    s.add_argument("--z", type=float, nargs=2, metavar=("ZMIN", "ZMAX"), help="z range of the first answer, µm")
    s.add_argument("--dz", type=float, help="plane spacing of the first answer, µm")
    s.add_argument(
        "--z-search",
        type=float,
        default=12.0,
        metavar="UM",
        help="look for each bead this far above and below the first answer's depth, µm (default %(default)s)",
    )
    s.add_argument("--device", choices=("cpu", "gpu"), help="where the models run (default: the configuration's)")
    s.add_argument("--json", action="store_true", help='print {"beads": [...]} as JSON instead of lines')
    s.set_defaults(func=cmd_beads)


def bead_line(i: int, bead) -> str:
    """One bead as a line of text: centre, diameter, RI and its check.

    Parameters
    ----------
    i : int
        Its number (1: the largest).
    bead : Bead

    Returns
    -------
    str
    """
    x, y, z = bead.centre_um
    r = bead.residual_over_noise
    check = "" if not bead.note else f"; CHECK: {bead.note}"
    voxels = (
        "" if bead.first_answer_ratio is None else f"; the voxel answer holds {bead.first_answer_ratio:.2f} x its Δn"
    )
    return (
        f"bead {i}: centre ({x:.2f}, {y:.2f}, {z:.2f}) µm, diameter {bead.diameter_um:.2f} µm, RI {bead.ri:.4f} "
        f"(Δn {bead.delta_n:+.4f}), residual {r if r is not None else float('nan'):.1f} x the noise{voxels}{check}"
    )


def cmd_beads(args) -> None:
    """Fit the beads of one frame and print them.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of ``ssdpc beads`` (see ``ssdpc beads --help``).
    """
    from napari_ssdpc.calibration.result import Calibration
    from napari_ssdpc.cli.options import config_from_args, optics_file
    from napari_ssdpc.io.frames import read_frame
    from napari_ssdpc.pipeline.job import Job
    from napari_ssdpc.progress import tqdm_callback
    from napari_ssdpc.reconstruction.beads import measure_beads

    if not (math.isfinite(args.z_search) and args.z_search >= 0):
        raise SsdpcError(f"--z-search must be a distance >= 0 µm, got {args.z_search}")
    cal = Calibration.from_json(args.calibration)
    cfg = config_from_args(args, None if args.optics is None else optics_file(args.optics), fallback=cal.optics)
    cfg = cfg.replace_reconstruction(method="tv")
    if args.medium_index is not None:
        cfg = cfg.replace(optics=cfg.optics.replace(medium_index=args.medium_index).to_dict())
    frame = read_frame(args.raw, allow_series=False, name="raw frame")
    flat = read_frame(args.flat, allow_series=False, name="flat frame") if args.flat else None
    with tqdm_callback("building operators", unit="plane") as cb:
        rec = Job(cfg, cal, flat).build(progress=cb)
    with tqdm_callback("fitting beads", unit="step") as cb:
        beads = measure_beads(rec, frame, name=Path(args.raw).name, progress=cb, z_search_um=args.z_search)
    if args.json:
        print(json.dumps({"beads": [b.to_dict() for b in beads]}, indent=2))
        return
    if not beads:
        print(f"no beads found in {Path(args.raw).name}: its first answer holds no object")
    for i, b in enumerate(beads, start=1):
        print(bead_line(i, b))
