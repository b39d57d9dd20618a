"""matplotlib plots in the dock, made when there is something to draw, drawn once per burst of events.

Importing matplotlib takes about 2 s of the GUI thread on a busy 2-core machine; the Slices and
Profile tabs would spend it while the dock opens. :class:`LazyFigure` makes its figure and canvas
on first use instead, and :func:`preload_matplotlib` imports matplotlib in a helper thread as soon
as the dock opens, so that first use finds it loaded. A new result layer, a step of the sliders or
a growing store send several events at once; :class:`Deferred` redraws once, on a turn of the event
loop of its own (a plot drawn inside the event that adds a layer lengthened napari's own stall).
"""

from __future__ import annotations

import threading

from napari_ssdpc._napari import turns

__all__ = ["Deferred", "LazyFigure", "preload_matplotlib"]


def _import_matplotlib() -> None:
    import matplotlib.figure  # noqa: F401  (the slow part: class and docstring set-up)
    from matplotlib.backends import backend_agg  # noqa: F401


def preload_matplotlib() -> threading.Thread:
    """Import matplotlib's figure in a daemon thread (the GUI thread keeps running).

    Returns
    -------
    threading.Thread
        The started thread.
    """
    thread = threading.Thread(target=_import_matplotlib, name="napari-ssdpc matplotlib import", daemon=True)
    thread.start()
    return thread


class Deferred:
    """Call ``fn`` once, on a turn of the event loop of its own (:func:`..turns.later`), however
    often it is asked before then.

    Parameters
    ----------
    fn : callable
        Takes no argument; a widget's redraw.
    """

    def __init__(self, fn):
        self.fn = fn

    def __call__(self, *_) -> None:
        """Ask for a call (event arguments are ignored)."""
        turns.later(self.fn, key=self)

    def flush(self) -> None:
        """Make the pending call now (nothing when none is pending)."""
        fn = turns.take(self)
        if fn is not None:
            fn()


class LazyFigure:
    """A matplotlib figure and its Qt canvas, added to ``layout`` when first used.

    Parameters
    ----------
    layout : QLayout
        Where the canvas goes (appended at the end).
    figsize : tuple of float
        Figure size, inches.
    min_height : int
        Smallest height of the canvas, px.
    """

    def __init__(self, layout, figsize: tuple[float, float], min_height: int):
        self._layout, self._figsize, self._min_height = layout, figsize, min_height
        self._figure = self._canvas = None

    @property
    def made(self) -> bool:
        """Whether the figure exists (something was drawn)."""
        return self._figure is not None

    @property
    def figure(self):
        """The matplotlib Figure (made now if needed)."""
        if self._figure is None:
            from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
            from matplotlib.figure import Figure

            self._figure = Figure(figsize=self._figsize, tight_layout=True)
            self._canvas = FigureCanvasQTAgg(self._figure)
            self._canvas.setMinimumHeight(self._min_height)
            self._layout.addWidget(self._canvas)
        return self._figure

    @property
    def canvas(self):
        """The Qt canvas of the figure (made now if needed)."""
        return self.figure.canvas

    def draw(self) -> None:
        """Redraw the canvas now (nothing when no figure was made): the callers draw on a turn of
        their own, where matplotlib's own deferred draw would join whatever Qt runs next."""
        if self._canvas is not None:
            self._canvas.draw()
