"""A camera source in the Reconstruct tab: the frames of a Micro-Manager core, reconstructed live.

Every frame of any acquisition (MDA) run on the core, whoever starts it (napari-micromanager's
buttons, a script), enters a bounded queue (:class:`~napari_ssdpc.pipeline.camera.CoreFrames`):
the acquisition is never held back, and when the solver lags the oldest waiting frame is dropped
and counted. The core is napari-micromanager's when it is loaded (pymmcore-plus's shared core),
else the one given to :meth:`LiveCamera.start`. The RI layer is updated in place with the newest
volume by a display timer, never by the solver; with a 'series to' store every kept frame is also
written there, with the frames kept and dropped in its metadata. Stop ends the run between frames
(the frames already waiting are finished); Cancel stops within an iteration. The status gives
the latency from a frame leaving the camera to its volume reconstructed, and to its layer shown.
"""

from __future__ import annotations

import time
from collections import deque
from pathlib import Path

from magicgui.widgets import PushButton, SpinBox
from qtpy.QtCore import QTimer

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.widgets.live import LIVE_MS, latency_text
from napari_ssdpc.errors import SsdpcError

__all__ = ["LiveCamera", "shared_core"]

#: Latencies kept for the status (the newest ones), frames.
KEEP_LATENCIES = 1000


def shared_core():
    """napari-micromanager's core (pymmcore-plus's shared instance), or None with the fix named.

    Returns
    -------
    pymmcore_plus.CMMCorePlus or None
    """
    try:
        from pymmcore_plus import CMMCorePlus
    except ImportError:
        notify.error("a camera needs pymmcore-plus: pip install 'napari-ssdpc[live]' (and napari-micromanager)")
        return None
    return CMMCorePlus.instance()


class LiveCamera:
    """The 'Micro-Manager core' controls of a :class:`~.reconstruct.ReconstructWidget`.

    Parameters
    ----------
    rc : ReconstructWidget
        The tab whose session, flat frame, outputs, store field and job runner are used.

    Attributes
    ----------
    frames : CoreFrames or None
        The running job's source.
    reconstructed_s, shown_s : collections.deque of float
        The newest latencies, s: from a frame leaving the camera to its volume reconstructed, and
        to its layer shown.
    """

    def __init__(self, rc):
        self.rc = rc
        self.queue = SpinBox(
            label="camera queue (frames)",
            min=0,
            max=1000,
            value=2,
            tooltip="most camera frames waiting for the solver; when it lags the oldest is dropped and counted "
            "(0: keep every frame, for a recording that must be complete)",
        )
        self.button = PushButton(
            text="Reconstruct the camera (Micro-Manager core)",
            tooltip="reconstruct every frame of the acquisitions run on the Micro-Manager core (napari-micromanager's) "
            "as it arrives; with a 'series to' store each kept frame is also written there",
        )
        self.button.changed.connect(lambda *_: self.stop() if self.frames is not None else self.start())
        self.widgets = [self.queue, self.button]
        self.frames = None
        self.reconstructed_s: deque[float] = deque(maxlen=KEEP_LATENCIES)
        self.shown_s: deque[float] = deque(maxlen=KEEP_LATENCIES)
        self._latest = None  # (frame, arrival time, result) of the newest reconstructed frame
        self._shown = -1
        self._timer = None

    def start(self, core=None):
        """Reconstruct the core's frames from now on (the message says why not, if it cannot).

        Parameters
        ----------
        core : pymmcore_plus.CMMCorePlus, optional
            Default: napari-micromanager's (pymmcore-plus's shared core).

        Returns
        -------
        worker or None
        """
        from napari_ssdpc.pipeline.camera import CoreFrames
        from napari_ssdpc.pipeline.sinks import LatestSink, ZarrSink

        rc = self.rc
        core = core if core is not None else shared_core()
        if core is None:
            return None
        store = str(rc.store.value or "")
        wanted = rc.quantities()
        try:
            job = rc.session.job(save=[q for q in wanted if q != "ri"])
            rc.session.remember()
            sink = (
                ZarrSink(Path(store), job.config.outputs.save, job.metadata("Micro-Manager core"))
                if store.endswith(".zarr")
                else LatestSink()  # only the newest volume is held
            )
            frames = CoreFrames(core, maxsize=int(self.queue.value) or None)
        except SsdpcError as e:
            notify.error(e)
            return None
        self.frames, self._latest, self._shown = frames, None, -1
        self.reconstructed_s.clear()
        self.shown_s.clear()
        worker = rc.runner.start(self._work(frames, job, rc.session.matching(job), sink), self._ended_text, "Camera")
        if worker is None:
            frames.close()
            self.frames = None
            return None
        self.button.text = "Stop the camera run"
        self._timer = QTimer()
        self._timer.timeout.connect(self.show)
        self._timer.start(LIVE_MS)
        worker.finished.connect(self._ended)
        return worker

    def stop(self) -> None:
        """End the run between frames: no new frame is taken, the waiting ones are finished."""
        if self.frames is not None:
            self.frames.close()

    def _work(self, frames, job, built, sink):
        """The job: every frame the queue keeps, until the acquisition is stopped here."""
        from napari_ssdpc.pipeline.run import Pipeline

        def work(progress, should_stop):
            progress(0, 0, "waiting for the camera's frames (start an acquisition on the core)")
            pipeline = Pipeline(job, reconstructor=built, progress=progress)

            def reconstructed(t, done, total, result):
                arrived = frames.arrived_at(t)
                if arrived is not None:
                    self.reconstructed_s.append(time.perf_counter() - arrived)
                self._latest = (t, arrived, result)
                progress(done, 0, f"camera frame {t} reconstructed ({len(frames.dropped())} dropped)")

            report = pipeline.run(
                frames,
                sink,
                progress=False,
                on_frame=reconstructed,
                iteration_progress=lambda d, n, label: progress(d, n, f"camera: {label}"),
                should_stop=should_stop,
            )
            return job, pipeline.reconstructor, report

        return work

    def show(self) -> None:
        """Show the newest reconstructed volume in place (the display's own beat, not the solver's)."""
        from napari_ssdpc._napari.layers import result_arrays, result_layer
        from napari_ssdpc._napari.widgets.common import show_layer

        latest = self._latest
        if latest is None or latest[0] == self._shown:
            return
        t, arrived, res = latest
        rc = self.rc
        origin = (float(res.z_um[0]), float(res.y_um[0]), float(res.x_um[0]))
        info = {"source": "Micro-Manager core", "frames": [t], "settings": res.settings}
        for q, a in result_arrays(res, rc.quantities()).items():
            data, kwargs, _ = result_layer(a, q, res.voxel_um, origin, name="camera", info=info, limits=False)
            if kwargs["name"] not in rc.viewer.layers:  # a later frame: the display stays as the user left it
                data, kwargs, _ = result_layer(a, q, res.voxel_um, origin, name="camera", info=info)
            show_layer(rc.viewer, data, kwargs)
        self._shown = t
        if arrived is not None:
            self.shown_s.append(time.perf_counter() - arrived)
            if rc.runner.running:
                rc.status.value = f"camera frame {t} shown {self.shown_s[-1]:.2f} s after it left the camera"

    def _ended_text(self, value) -> str:
        """The run's end: operators kept, the last volume shown, frames kept and dropped, latency."""
        job, rec, report = value
        self.rc.session.built = (job, rec)
        self.rc.session.operators_built.emit(rec)
        self.show()
        dropped = f"{len(report.dropped)} dropped while the solver lagged" if report.dropped else "none dropped"
        return (
            f"camera: {report.written} of {report.frames} frames reconstructed, {dropped}; latency from camera to "
            f"volume {latency_text(self.reconstructed_s)}, to layer shown {latency_text(self.shown_s)}"
        )

    def _ended(self) -> None:
        """The job has finished, been stopped or failed: the core let go, the timer stopped."""
        if self.frames is not None:
            self.frames.close()
            self.frames = None
        if self._timer is not None:
            self._timer.stop()
            self._timer = None
        self.show()
        self.button.text = "Reconstruct the camera (Micro-Manager core)"
