"""A store being written, shown as it grows, without reading it on the GUI thread.

A series streamed into an OME-Zarr store, or a followed recording, is shown from disk while the
worker writes it. Each look at the store (:meth:`StoreView.refresh`, on a timer) reads the frames
done and the layers' metadata in a helper thread; a layer new to the viewer also gets its display
limits there (they read a frame). The layers are then shown on turns of the event loop of their
own (:mod:`.turns`); a look asked for while one is under way is made once it has arrived.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from qtpy.QtCore import QObject, Signal

from napari_ssdpc._napari import notify, turns
from napari_ssdpc._napari.widgets.common import show_in_turns
from napari_ssdpc._napari.widgets.jobs import start_helper
from napari_ssdpc.errors import SsdpcError

__all__ = ["StoreView"]


#: Views with a read under way, kept alive until it arrives (a view replaced meanwhile would take its
#: receiver with it, and the read, counted as pending by the turns, would never arrive).
_READING: set[StoreView] = set()


class _Arrivals(QObject):
    """Hands a helper thread's reading to the GUI thread (a queued Qt signal)."""

    read = Signal(object)


class StoreView:
    """The layers of a store being written, shown again each time it has more frames.

    Parameters
    ----------
    viewer : napari.Viewer
    on_shown : callable, optional
        ``on_shown(done)`` on the turn after the layers holding the frames ``done`` (list of int)
        were shown.

    Attributes
    ----------
    frames : int
        The number of frames shown (-1 before the first look).
    """

    def __init__(self, viewer, on_shown=None):
        self.viewer, self.on_shown = viewer, on_shown
        self.frames = -1
        self._again: Path | None = None
        self._arrivals = _Arrivals()
        self._arrivals.read.connect(self._arrived)

    def refresh(self, store: Path) -> None:
        """Look at the store again (in a helper thread); its new frames are shown when read.

        Parameters
        ----------
        store : Path
            The OME-Zarr store being written.
        """
        if self in _READING:
            self._again = store
            return
        _READING.add(self)
        turns.expect()
        known = {lyr.name for lyr in self.viewer.layers}
        start_helper(partial(self._read, Path(store), known, self.frames), "napari-ssdpc store view")

    def _read(self, store: Path, known: set, shown: int) -> None:
        from napari_ssdpc._napari.reader import read_result
        from napari_ssdpc.io.store import done_frames

        done, layers, error = [], None, None
        try:
            if store.is_dir() and (store / "ri").is_dir():
                done = [int(t) for t in done_frames(store)]
                if done and len(done) != shown:
                    layers = read_result(store, limits=False)  # metadata only
                    if not all(kw["name"] in known for _, kw, _ in layers):
                        layers = read_result(store)  # a new layer: its display limits from the data
        except SsdpcError as e:
            error = str(e)
        except Exception:  # a store half created by the worker: nothing done yet, read on the next look
            done, layers = [], None
        self._arrivals.read.emit((store, done, layers, error))

    def _arrived(self, reading) -> None:
        store, done, layers, error = reading
        _READING.discard(self)
        turns.arrived()
        if error is not None:
            notify.error(error)
        elif layers is not None:
            self.frames = len(done)
            show_in_turns(self.viewer, layers, key=self)  # a newer reading replaces one still waiting
            if self.on_shown is not None:
                turns.later(partial(self.on_shown, done), key=(self, "shown"))
        if self._again is not None:
            again, self._again = self._again, None
            self.refresh(again)
