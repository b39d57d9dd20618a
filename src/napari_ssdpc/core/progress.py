"""Progress reporting: core functions take ``progress(done, total)`` callables."""

from __future__ import annotations

import contextlib
import sys

from tqdm.auto import tqdm


@contextlib.contextmanager
def tqdm_callback(desc: str, unit: str = "step"):
    """A ``progress(done, total)`` callable that drives a tqdm bar on stderr."""
    bar = tqdm(desc=desc, unit=unit, file=sys.stderr, leave=False, dynamic_ncols=True)

    def update(done, total):
        if bar.total != total:
            bar.total = total
        bar.n = done
        bar.refresh()

    try:
        yield update
    finally:
        bar.close()
