"""The ``ssdpc`` console entry point: the command's modules (about a second of imports) are loaded
inside the guard, so Ctrl-C at any moment ends in one line, never a traceback."""

from __future__ import annotations

import sys

__all__ = ["run"]


def run(argv=None) -> int:
    """Load and run `ssdpc` (:func:`napari_ssdpc.cli.main.main`).

    Parameters
    ----------
    argv : list of str, optional
        Passed on.

    Returns
    -------
    int
        Its exit code, or 130 when interrupted while it loads.
    """
    try:
        from napari_ssdpc.cli.main import main

        return main(argv)
    except KeyboardInterrupt:
        sys.stderr.write("ssdpc: interrupted\n")
        return 130
