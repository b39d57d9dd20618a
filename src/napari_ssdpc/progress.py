"""Progress reporting: core functions take ``progress(done, total)`` callables."""

from __future__ import annotations

import contextlib
import sys

from tqdm.auto import tqdm


@contextlib.contextmanager
def tqdm_callback(desc: str, unit: str = "step", disable: bool = False):
    """A ``progress(done, total)`` callable that drives a tqdm bar on stderr.

    Parameters
    ----------
    desc : str
        The bar's label.
    unit : str
        What one step is ("plane", "frame", "iteration").
    disable : bool
        No bar (the work runs elsewhere).

    Yields
    ------
    callable
        ``update(done, total, label='')``: sets the bar to ``done`` of ``total``; a new ``label``
        (a stage of the work) is shown beside ``desc`` and restarts the bar. On a terminal the bar
        redraws every 0.5 s; in a log file every 10 s.
    """
    tty = sys.stderr.isatty()
    # in a log file, a line every 10 s is enough
    bar = tqdm(
        desc=desc,
        unit=unit,
        file=sys.stderr,
        leave=False,
        dynamic_ncols=True,
        mininterval=0.5 if tty else 10,
        disable=disable,
    )

    stage = ""

    def update(done, total, label="", *_):
        nonlocal stage
        restart = bool(label) and label != stage
        if restart:  # a new stage of the work (e.g. "TV", then "multislice")
            stage = label
            bar.set_description(f"{desc} ({label})", refresh=False)
            bar.reset(total=total)
        elif bar.total != total:
            bar.reset(total=total)
        bar.update(done - bar.n)
        if restart:  # shown at once with its count (the bar's own redraws wait for its interval)
            bar.refresh()

    try:
        yield update
    finally:
        bar.close()
