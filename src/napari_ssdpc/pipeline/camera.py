"""Frames from a camera on a Micro-Manager core (pymmcore-plus): every frame of any acquisition
(MDA) run on that core, whoever started it, into the frame loop.

The core's ``mda.events.frameReady`` (connected directly, also for Qt signals) pushes each frame
into a bounded queue (:class:`~napari_ssdpc.pipeline.sources.LiveFrames`): the acquisition thread
never waits for the solver; when the solver lags, the oldest waiting frame is dropped and counted. The acquisition's
``sequenceFinished`` (or :meth:`CoreFrames.close`) ends the source, and the loop ends after the
frames it kept. pymmcore-plus is an optional dependency (``pip install -e ".[live]"``); this module
only uses the core it is given.
"""

from __future__ import annotations

import sys

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.pipeline.sources import LiveFrames

__all__ = ["CoreFrames"]


class CoreFrames(LiveFrames):
    """The frames of the acquisitions run on a pymmcore-plus core, as a frame source.

    Parameters
    ----------
    core : pymmcore_plus.CMMCorePlus
        The core (e.g. napari-micromanager's); its camera's image size is the frame shape.
    maxsize : int or None
        Most frames waiting for the solver (older ones are dropped); None keeps every frame.
    name : str
        For messages.

    Examples
    --------
    >>> frames = CoreFrames(core)                       # doctest: +SKIP
    >>> core.run_mda(MDASequence(time_plan={"interval": 0, "loops": 100}))
    >>> report = pipeline.run(frames, sink)             # returns when the acquisition finishes
    >>> report.dropped                                  # frames the solver could not keep up with
    """

    def __init__(self, core, maxsize: int | None = 2, name: str = "Micro-Manager core"):
        try:
            shape = (int(core.getImageHeight()), int(core.getImageWidth()))
        except Exception:  # a core without a camera
            shape = (0, 0)
        if min(shape) <= 0:
            raise SsdpcError(f"{name}: the core has no camera image; load and set a camera device first")
        super().__init__(shape, name, maxsize)
        self._core = core
        self._error: str | None = None
        _connect_direct(core.mda.events.frameReady, self._on_frame)
        _connect_direct(core.mda.events.sequenceFinished, self._on_finished)

    def _on_frame(self, image, *_) -> None:
        """The acquisition thread's frame: queued, never waited on."""
        if LiveFrames.finished(self):
            return
        if tuple(image.shape[:2]) != self.frame_shape:
            self._error = (
                f"{self.name}: the camera's frames changed from {self.frame_shape} to {tuple(image.shape[:2])} "
                "during the run; keep the camera ROI and binning fixed while reconstructing"
            )
            self.close()
            return
        self.push(image)

    def _on_finished(self, *_) -> None:
        self.close()

    def close(self) -> None:
        """No more frames: the core's signals are let go and the loop ends after the kept ones."""
        events = self._core.mda.events
        for signal, slot in ((events.frameReady, self._on_frame), (events.sequenceFinished, self._on_finished)):
            try:
                signal.disconnect(slot)
            except Exception:  # already let go
                pass
        super().close()

    def finished(self) -> bool:
        """The acquisition ended (or :meth:`close`); a frame of another shape ends it with its error.

        Raises
        ------
        SsdpcError
            The camera's frame shape changed during the run.
        """
        if self._error is not None:
            raise SsdpcError(self._error)
        return super().finished()


def _connect_direct(signal, slot) -> None:
    """Connect so that ``slot`` runs in the thread that emits (the acquisition's), whatever the core's
    signal backend: with Qt signals (a core in a Qt application, as napari-micromanager's) a plain
    connection would queue every frame to the GUI thread's event loop, which a script or a CLI run
    blocking in the frame loop never turns. The slot only takes a lock and copies the frame."""
    module = sys.modules.get(type(signal).__module__)
    qt = getattr(module, "Qt", None)  # a Qt binding's bound signal: its own QtCore module names the type
    if qt is None:  # psygnal: slots run in the emitting thread
        signal.connect(slot)
        return
    signal.connect(slot, qt.ConnectionType.DirectConnection)
