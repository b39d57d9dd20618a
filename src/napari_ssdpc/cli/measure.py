"""``ssdpc measure``: per-object measurements over time, from a result to ``RESULT_objects.csv``."""

from __future__ import annotations

from napari_ssdpc.analysis.objects import DEFAULT_RESOLUTION_UM, ObjectRule
from napari_ssdpc.analysis.tracks import DEFAULT_MAX_STEP_UM

__all__ = ["add_measure_command", "cmd_measure"]


def add_measure_command(sub) -> None:
    """Add ``measure`` to the subcommands of ``ssdpc``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``ssdpc`` parser.
    """
    rule = ObjectRule()
    s = sub.add_parser(
        "measure",
        help="segment the objects of a result and measure each over time (CSV beside the result)",
        description="Objects are voxels above K x the background noise of Δn and FRACTION of the peak Δn "
        "(hysteresis down to K_LOW and FRACTION_LOW), connected; per object and frame: centroid, volume, "
        "mean and peak RI, dry mass (docs/measurements.md).",
    )
    s.add_argument("result", help="OUT.ome.tif or OUT.zarr written by `ssdpc reconstruct`")
    s.add_argument("-o", "--output", help="CSV to write (default: RESULT_objects.csv beside the result)")
    s.add_argument("--k", type=float, default=rule.k, help="seed threshold, in noise σ of Δn (default %(default)s)")
    s.add_argument(
        "--k-low", type=float, default=rule.k_low, help="hysteresis threshold, in noise σ of Δn (default %(default)s)"
    )
    s.add_argument(
        "--fraction",
        type=float,
        default=rule.fraction,
        help="seed threshold at least this fraction of the peak Δn (default %(default)s)",
    )
    s.add_argument(
        "--fraction-low",
        type=float,
        default=rule.fraction_low,
        help="hysteresis threshold at least this fraction of the peak Δn (default %(default)s)",
    )
    s.add_argument(
        "--min-volume", type=float, default=rule.min_volume_um3, help="drop smaller objects, µm³ (default %(default)s)"
    )
    s.add_argument(
        "--resolution",
        type=float,
        nargs=2,
        default=DEFAULT_RESOLUTION_UM,
        metavar=("FWHM_Z", "FWHM_XY"),
        help="the reconstruction's resolution, µm: each object's margin and the blur removed from its volume "
        "(default %(default)s)",
    )
    s.add_argument(
        "--sign",
        choices=("denser", "lighter"),
        default=rule.sign,
        help="objects above or below the medium (default %(default)s)",
    )
    s.add_argument("--noise", type=float, help="background σ of Δn (default: 1.4826 x MAD of each frame)")
    s.add_argument(
        "--refraction-increment",
        type=float,
        help="specific refraction increment α for the dry mass, µm³/pg (default: the result's)",
    )
    s.add_argument(
        "--max-step",
        type=float,
        default=DEFAULT_MAX_STEP_UM,
        help="tracks: the largest step between frames, µm (default %(default)s)",
    )
    s.add_argument("--overwrite", action="store_true", help="replace an existing CSV napari-ssdpc did not write")
    s.set_defaults(func=cmd_measure)


def cmd_measure(args) -> None:
    """Measure the objects of every frame of a result and write the CSV.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc measure` (see ``ssdpc measure --help``).
    """
    from napari_ssdpc.analysis.table import measure_result
    from napari_ssdpc.progress import tqdm_callback

    rule = ObjectRule(
        k=args.k,
        k_low=args.k_low,
        fraction=args.fraction,
        fraction_low=args.fraction_low,
        min_volume_um3=args.min_volume,
        resolution_um=tuple(args.resolution),
        sign=args.sign,
        noise=args.noise,
    )
    with tqdm_callback("measuring", unit="frame") as cb:
        rows, path = measure_result(
            args.result,
            args.output,
            rule=rule,
            refraction_increment_um3_pg=args.refraction_increment,
            max_step_um=args.max_step,
            overwrite=args.overwrite,
            progress=cb,
        )
    frames = len({r["t"] for r in rows})
    tracks = len({r["track"] for r in rows})
    print(f"wrote {path}: {len(rows)} object(s) found in {frames} frame(s), {tracks} track(s)")
