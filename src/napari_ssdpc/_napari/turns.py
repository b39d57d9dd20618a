"""Work on the GUI thread, one piece per turn of the event loop.

Qt runs the posted events and the due timers of one pass back to back: a result's layers added in
one event, a plot drawn right after a layer was added, or a progress bar that processes events
inside a handler (napari's does) add up to one long stall, however short each piece is. A piece
handed to :func:`later` runs alone on a turn of its own, :data:`TURN_MS` after the previous piece
ended: napari draws, the user's clicks are handled and timers fire between any two pieces.

There is one GUI thread per process, hence one queue. A piece asked for again before it ran (a
plot's redraw after every slider step) runs once, at its first place in the queue.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable

from napari_ssdpc._napari import notify
from napari_ssdpc.errors import SsdpcError

__all__ = ["TURN_MS", "arrived", "expect", "later", "pending", "take"]

#: Time between the end of one piece and the start of the next, ms: long enough for a timer that
#: fell due during a piece to fire first.
TURN_MS = 10

_queue: dict[Hashable, Callable[[], object]] = {}  # insertion-ordered: the order of the requests
_scheduled = [False]
_expected = [0]  # pieces being prepared elsewhere (a helper thread's read), not queued yet


def later(fn: Callable[[], object], key: Hashable | None = None) -> None:
    """Run ``fn()`` on a turn of the event loop of its own, after the pieces asked for before it.

    Parameters
    ----------
    fn : callable
        Takes no argument. A ``SsdpcError`` it raises is shown as a napari error; a ``RuntimeError``
        (its widget or viewer closed meanwhile) drops it.
    key : hashable, optional
        A piece asked for with the key of one still waiting replaces that one, at its place.
    """
    _queue[object() if key is None else key] = fn
    _schedule()


def take(key: Hashable) -> Callable[[], object] | None:
    """Take the piece waiting under ``key`` out of the queue (to run it now); None when none waits.

    Parameters
    ----------
    key : hashable

    Returns
    -------
    callable or None
    """
    return _queue.pop(key, None)


def expect() -> None:
    """Count a piece being prepared off the GUI thread as pending until :func:`arrived`."""
    _expected[0] += 1


def arrived() -> None:
    """A piece counted by :func:`expect` has arrived (queued with :func:`later`, or not needed)."""
    _expected[0] -= 1


def pending() -> int:
    """The number of pieces still to run or still being prepared."""
    return len(_queue) + _expected[0]


def _schedule() -> None:
    if _queue and not _scheduled[0]:
        from qtpy.QtCore import QTimer

        _scheduled[0] = True
        QTimer.singleShot(TURN_MS, _turn)


def _turn() -> None:
    _scheduled[0] = False
    if not _queue:
        return
    fn = _queue.pop(next(iter(_queue)))
    try:
        fn()
    except SsdpcError as e:
        notify.error(str(e))
    except RuntimeError:  # its widget's Qt objects were deleted, or its viewer closed
        pass
    finally:
        _schedule()
