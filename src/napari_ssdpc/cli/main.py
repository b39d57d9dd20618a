"""The ``ssdpc`` command line tool.

Bad input ends with one line ``ssdpc: error: ...`` that names the fix, and exit code 2;
never a traceback. Progress bars go to stderr.
"""

from __future__ import annotations

import argparse
import errno
import os
import re
import sys
import warnings

from napari_ssdpc import __version__
from napari_ssdpc.cli.beads import add_beads_command
from napari_ssdpc.cli.commands import (
    PHANTOMS,
    cmd_bench,
    cmd_calibrate,
    cmd_demo,
    cmd_design,
    cmd_reconstruct,
    cmd_resign,
    cmd_simulate,
)
from napari_ssdpc.cli.dpc import add_dpc_command
from napari_ssdpc.cli.fit_optics import add_fit_optics_command
from napari_ssdpc.cli.measure import add_measure_command
from napari_ssdpc.cli.options import add_reconstruction_options
from napari_ssdpc.errors import SsdpcError, SsdpcWarning

__all__ = ["build_parser", "main"]

#: Numbers such as -1e3, -.5 or -inf are values, not options (argparse knows only -1 and -1.5).
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|nan)$", re.IGNORECASE)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser that reads -1e3 as a number, so that ``--z -1e3 1e3`` parses, and reports a
    wrong command line in one line that names its help (argparse prints its usage line first)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str):
        """Exit with status 2 and one line: the fault and where the options are listed."""
        line = " ".join(message.split())
        self.exit(2, f"{self.prog}: error: {line}; see `{self.prog} --help`\n")


# ------------------------------------------------------------------------- parser
def build_parser():
    """The `ssdpc` argument parser with its sub-commands.

    Returns
    -------
    argparse.ArgumentParser
        Errors print one line with the fix and exit with status 2.
    """
    p = _Parser(
        prog="ssdpc",
        description="Single-shot 3D quantitative phase imaging with a Fourier light-field microscope (ssDPC).",
    )
    p.add_argument("--version", action="version", version=f"napari-ssdpc {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    overwrite_help = (
        "replace existing output files (and the overlay or OUT_<name>.ome.tif beside them) "
        "that napari-ssdpc did not write"
    )
    optics_help = "optics YAML (schema of docs/paper-optics.yaml); default: the paper's optics"

    s = sub.add_parser("design", help="print the design numbers of an optics file (paper Eqs. 8-14)")
    s.add_argument("--optics", help=optics_help)
    s.add_argument("--json", action="store_true", help="print JSON instead of a table")
    s.set_defaults(func=cmd_design)

    s = sub.add_parser("calibrate", help="detect the lenslet grid on a white (condenser fully open) frame")
    s.add_argument("frame", help="white frame TIFF")
    s.add_argument("--optics", help=optics_help)
    s.add_argument("-o", "--output", required=True, help="calibration JSON to write (a PNG overlay goes beside it)")
    s.add_argument(
        "--axis",
        type=float,
        nargs=2,
        metavar=("X", "Y"),
        help="the optical axis on the sensor, px, where the frame cannot show it (every EI lit); "
        "default: measured from the EI brightness",
    )
    s.add_argument("--overwrite", action="store_true", help=overwrite_help)
    s.set_defaults(func=cmd_calibrate)

    add_fit_optics_command(sub)

    s = sub.add_parser("resign-calibration", help="accept a deliberately edited calibration JSON (new checksum)")
    s.add_argument("calibration", help="calibration JSON written by `ssdpc calibrate`, edited by hand")
    s.set_defaults(func=cmd_resign)

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
    s.add_argument("--overwrite", action="store_true", help=overwrite_help)
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("reconstruct", help="reconstruct the 3D refractive index of a raw frame or time series")
    s.add_argument(
        "raw",
        help="raw light-field frame or (t, y, x) series: TIFF/OME-TIFF, OME-Zarr, or with --follow a folder of TIFFs",
    )
    s.add_argument("--optics", help="optics YAML; default: the optics stored in the calibration")
    s.add_argument("--calibration", required=True, help="calibration JSON from `ssdpc calibrate`")
    s.add_argument("--flat", help="flat frame (no sample, same condenser NA) for flat-fielding")
    add_reconstruction_options(s)
    s.add_argument(
        "-o", "--output", required=True, help="OUT.ome.tif (one frame) or OUT.zarr (time series; a rerun resumes it)"
    )
    s.add_argument("--workers", type=int, help="spread the frames of a series over a local Dask cluster of N workers")
    s.add_argument("--scheduler", help="spread the frames over an existing Dask cluster (tcp://host:8786)")
    s.add_argument(
        "--follow",
        action="store_true",
        help="reconstruct a recording still being written (a growing TIFF or OME-Zarr, or a folder of TIFF files) "
        "into OUT.zarr as its frames arrive; Ctrl-C stops, a rerun resumes",
    )
    s.add_argument(
        "--idle",
        type=float,
        default=60.0,
        metavar="SECONDS",
        help="with --follow: stop when no frame has arrived for this long (default 60)",
    )
    s.add_argument("--overwrite", action="store_true", help=overwrite_help)
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
    s.add_argument("--seed", type=int, default=0, help="random seed of the camera noise (>= 0)")
    s.add_argument(
        "--refine",
        action=argparse.BooleanOptionalAction,
        default=True,
        help=(
            "also refine with --method multislice (about 7 min on 2 cores): ri_multislice.ome.tif, refined.png "
            "(default: yes)"
        ),
    )
    s.add_argument(
        "--overwrite", action="store_true", help="replace files in the folder that napari-ssdpc did not write"
    )
    s.set_defaults(func=cmd_demo)
    add_measure_command(sub)
    add_beads_command(sub)
    add_dpc_command(sub)
    return p


class _WarningLines:
    """Shows each warning as one line, and a warning that repeats frame after frame (the same text
    but for the frame and its numbers) once, with a count of its repeats at the end of the run."""

    def __init__(self):
        self.repeats: dict[str, list] = {}

    def show(self, message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        kind = re.sub(r"\d+(\.\d+)?", "#", text)
        if kind in self.repeats:
            self.repeats[kind][1] += 1
            return
        self.repeats[kind] = [text, 0]
        _line(f"ssdpc: warning: {text}")

    def summary(self) -> None:
        for text, more in self.repeats.values():
            if more:
                short = re.sub(r"\S*[\\/]", "", text)[:70]  # folders left out of the paths
                _line(f"ssdpc: warning: {more} more like '{short}...' (other frames or numbers)")


def _line(text: str) -> None:
    """One line on stderr, on a line of its own above a progress bar that is being drawn."""
    from tqdm import tqdm

    tqdm.write(text, file=sys.stderr)


def main(argv=None) -> int:
    """Run `ssdpc`: every known fault ends in one line on stderr, never a traceback.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 on an error, 130 when interrupted.
    """
    args = build_parser().parse_args(argv)
    lines = _WarningLines()
    warnings.showwarning = lines.show
    warnings.simplefilter("always", SsdpcWarning)
    try:
        fault = _fault_of(args)
    except KeyboardInterrupt:
        lines.summary()
        sys.stderr.write("ssdpc: interrupted\n")
        return 130
    lines.summary()
    return 0 if fault is None else _error(fault)


def _fault_of(args) -> str | None:
    """Run the command; None, or the one-line message of what went wrong."""
    try:
        args.func(args)
    except SsdpcError as e:
        return str(e)
    except MemoryError:
        return "out of memory; narrow --z, take a larger --dz or close other programs"
    except RecursionError:
        return "an input file is nested too deeply to be read; check the settings and calibration files"
    except OSError as e:  # a file-system fault that no check foresaw (full disk, lost mount, ...)
        from napari_ssdpc.files import os_error

        full = e.errno is None and "written" in str(e)  # numpy's short write on a full disk
        doing = "writing" if full or e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS) else "accessing"
        return str(os_error(e, e.filename or "a file", doing))
    except Exception as e:  # a fault no check foresaw: still one line; SSDPC_DEBUG=1 shows the traceback
        if os.environ.get("SSDPC_DEBUG"):
            raise
        return (
            f"unexpected {type(e).__name__}: {str(e)[:200]}; this is a fault of napari-ssdpc, not of your input: "
            "rerun with SSDPC_DEBUG=1 and report the traceback"
        )
    return None


def _error(message: str) -> int:
    sys.stderr.write(f"ssdpc: error: {' '.join(message.split())}\n")
    return 2


if __name__ == "__main__":
    sys.exit(main())
