"""A live source in the Reconstruct tab: follow a recording while it is written.

A growing TIFF, a (t, y, x) OME-Zarr image whose t axis grows, or a folder of TIFF files (see
:class:`~napari_ssdpc.io.followed.FollowedFrames`) is reconstructed frame by frame into the
OME-Zarr store of the tab's 'series to' field, in a worker (the resumable writer of
``ssdpc reconstruct --follow``). The result layers are read back from the store and grow in place
as frames finish. The status gives the latency from a frame on disk to its volume written, and
to its layer shown. Cancel stops between iterations (the store keeps every finished frame and a
rerun resumes); the run ends by itself once no frame has arrived for the idle time.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from magicgui.widgets import FileEdit, FloatSpinBox, PushButton

from napari_ssdpc._napari import notify
from napari_ssdpc.errors import Cancelled, SsdpcError

__all__ = ["LIVE_MS", "LiveFollow", "latency_text"]

#: How often the store of a followed recording is shown again while it runs, ms.
LIVE_MS = 250


def latency_text(seconds) -> str:
    """Median and max of latencies, e.g. '0.42 s (median), 0.61 s (max)' ('none' without any).

    Parameters
    ----------
    seconds : iterable of float
        Latencies, s.

    Returns
    -------
    str
    """
    values = list(seconds)
    return f"{np.median(values):.2f} s (median), {max(values):.2f} s (max)" if values else "none"


class LiveFollow:
    """The 'follow a recording' controls of a :class:`~.reconstruct.ReconstructWidget`.

    Parameters
    ----------
    rc : ReconstructWidget
        The tab whose session, flat frame, outputs, store field and job runner are used.

    Attributes
    ----------
    written_s, shown_s : dict of int to float
        Per frame of the current run: seconds from the frame complete on disk
        (``FollowedFrames.arrived_at``) to its volume written to the store, and to its layer shown.
    """

    def __init__(self, rc):
        self.rc = rc
        self.recording = FileEdit(mode="r", filter="*.tif *.tiff")
        self.recording.label = "recording"
        self.recording.tooltip = (
            "a recording still being written, to follow: a TIFF growing page by page, a (t, y, x) OME-Zarr "
            "image (NAME.zarr) or a folder of TIFF files (one frame each; type the folder's path); it may "
            "appear after Follow is pressed (within the idle time)"
        )
        self.idle = FloatSpinBox(
            label="stop when idle (s)",
            min=0.5,
            max=3600.0,
            step=1.0,
            value=30.0,
            tooltip="following ends once no new frame has arrived for this long, s (Cancel ends it at once)",
        )
        self.button = PushButton(
            text="Follow a recording",
            tooltip="reconstruct each frame of the recording as it arrives into the 'series to' store, shown from disk",
        )
        self.button.changed.connect(lambda *_: self.start())
        self.widgets = [self.recording, self.idle, self.button]
        self.source = None  # the FollowedFrames of the running job, once its first frame arrived
        self.written_s: dict[int, float] = {}
        self.shown_s: dict[int, float] = {}
        self._summary = None  # (store, report, idle_s) of the run that ended

    def start(self):
        """Follow the chosen recording into the chosen store (the message says why not, if it cannot).

        Returns
        -------
        worker or None
        """
        from napari_ssdpc.pipeline.sinks import ZarrSink

        rc = self.rc
        path, store = str(self.recording.value or ""), str(rc.store.value or "")
        if path in ("", "."):
            notify.error("choose the recording to follow (a TIFF, an OME-Zarr image or a folder of TIFF files)")
            return None
        if not store.endswith(".zarr"):
            notify.error("choose the store to write in 'series to' (NAME.zarr) before following a recording")
            return None
        wanted = rc.quantities()
        try:
            job = rc.session.job(save=[q for q in wanted if q != "ri"])
            rc.session.remember()
            sink = ZarrSink(Path(store), job.config.outputs.save, job.metadata(Path(path).name))
        except SsdpcError as e:
            notify.error(e)
            return None
        built = rc.session.matching(job)
        self.source, self.written_s, self.shown_s = None, {}, {}
        work = self._work(path, float(self.idle.value), job, built, sink)
        worker = rc.runner.start(work, lambda r: self._followed(job, *r, Path(store)), "Follow")
        if worker is None:
            return None
        self.button.enabled = False
        self._summary = None
        rc.watch(Path(store), worker, on_shown=self._shown, every_ms=LIVE_MS)
        worker.finished.connect(lambda: setattr(self.button, "enabled", True))
        return worker

    def _work(self, path: str, idle_s: float, job, built, sink):
        """The job: wait for the first frame, then reconstruct every frame as it arrives."""
        from napari_ssdpc.io.followed import FollowedFrames
        from napari_ssdpc.pipeline.run import Pipeline

        name = Path(path).name

        def work(progress, should_stop):
            progress(0, 0, f"waiting for the first frame of {name}")
            try:  # waits for the recording to appear and for its first frame
                source = FollowedFrames(path, idle_s=idle_s, should_stop=should_stop)
            except SsdpcError:
                if should_stop():
                    raise Cancelled("cancelled") from None
                raise
            self.source = source
            pipeline = Pipeline(job, reconstructor=built, progress=progress)

            def written(t, done, total, _result):
                self.written_s[t] = time.time() - source.arrived_at.get(t, time.time())
                progress(done, 0, f"{name}: frame {t} written {self.written_s[t]:.2f} s after it was on disk")

            report = pipeline.run(
                source,
                sink,
                progress=False,
                on_frame=written,
                iteration_progress=lambda d, n, label: progress(d, n, f"{name}: {label}"),
                should_stop=should_stop,
            )
            return pipeline.reconstructor, report, idle_s

        return work

    def _shown(self, done: list[int]) -> None:
        """The store's layers holding the frames ``done`` were just shown: each new frame of this
        run that was written is noted as shown now; the run's summary, once it has ended, follows."""
        source = self.source
        if source is not None:
            now = time.time()  # after the display, and after every write time counted below was taken
            new = [t for t in done if t in self.written_s and t not in self.shown_s]
            for t in new:
                self.shown_s[t] = now - source.arrived_at[t]
            if new and self.rc.runner.running:
                t = new[-1]
                self.rc.status.value = f"{source.path.name}: frame {t} shown {self.shown_s[t]:.2f} s after on disk"
        if self._summary is not None and not self.rc.runner.running:
            self.rc.status.value = self._summary_text()

    def _followed(self, job, rec, report, idle_s: float, store: Path) -> str:
        """The job's end (no new frame for the idle time): operators kept, last frames shown, latency."""
        self.rc.session.built = (job, rec)
        self.rc.session.operators_built.emit(rec)
        self._summary = (store, report, idle_s)  # written again once the last frames are shown
        return self._summary_text()

    def _summary_text(self) -> str:
        store, report, idle_s = self._summary
        return (
            f"{store.name}: {report.written} new frames, {report.frames} in all ({report.skipped} done before); "
            f"latency from frame on disk to volume written {latency_text(self.written_s.values())}, to layer shown "
            f"{latency_text(self.shown_s.values())}; no new frame for {idle_s:g} s: stopped"
        )
