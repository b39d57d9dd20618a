"""Long work off the GUI thread: one job at a time per widget, with progress and Cancel.

Every long step runs in a generator ``thread_worker``. The core function runs in a helper thread
and reports ``progress(done, total, label)``; the generator relays each report with ``yield``, so
napari's progress bar and the widget's status follow it. Cancel sets a stop flag that the core
checks every iteration (``should_stop``) and that the progress callback checks at every report,
so a job stops within one iteration. Layers are only touched in the ``yielded``/``returned``
callbacks, on the main thread. A ``SsdpcError`` becomes a napari error with the core's one-line
message, a ``SsdpcWarning`` a napari warning (once per job).
"""

from __future__ import annotations

import atexit
import queue
import threading
import time
from dataclasses import dataclass
from functools import partial

from magicgui.widgets import Label, PushButton
from napari.qt.threading import create_worker
from napari.utils import progress as napari_progress

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.turns import later
from napari_ssdpc.errors import SsdpcError, SsdpcWarning

__all__ = ["PROGRESS_EVERY_S", "JobRunner", "Outcome", "Partial", "start_helper"]

#: Shortest time between two progress updates on screen, s (the last step of a stage always shows).
PROGRESS_EVERY_S = 0.25


@dataclass
class Outcome:
    """How a job ended: its value, the one-line error of a SsdpcError, or cancelled."""

    value: object = None
    error: str | None = None
    cancelled: bool = False


#: Running jobs' (thread, stop flag): stopped and joined when the interpreter exits (a job torn down
#: inside an FFT made napari's exit abort: "terminate called without an active exception").
_RUNNING: set[tuple[threading.Thread, threading.Event]] = set()


@atexit.register
def _stop_jobs() -> None:
    for _, stop in list(_RUNNING):
        stop.set()
    for thread, _ in list(_RUNNING):
        thread.join(timeout=30.0)


def _room_for_one_more() -> None:
    """napari's workers share Qt's global thread pool, as many threads as cores: on 2 cores a job
    beside a followed recording and a movie would wait, unseen, for one of them to end. Each job
    relays a helper thread (it waits, it does not compute): the pool grows to start it now."""
    from qtpy.QtCore import QThreadPool

    pool = QThreadPool.globalInstance()
    pool.setMaxThreadCount(max(pool.maxThreadCount(), pool.activeThreadCount() + 1))


def start_helper(target, name: str, stop: threading.Event | None = None) -> threading.Thread:
    """Start ``target()`` in a daemon thread that the interpreter's exit stops and waits for (a
    thread torn down inside a C library aborts the exit).

    Parameters
    ----------
    target : callable
    name : str
        The thread's name.
    stop : threading.Event, optional
        Set at exit (the target's ``should_stop``); a short read needs none.

    Returns
    -------
    threading.Thread
    """
    flag = stop or threading.Event()

    def run():
        try:
            target()
        finally:
            _RUNNING.discard((thread, flag))

    thread = threading.Thread(target=run, name=name, daemon=True)
    _RUNNING.add((thread, flag))
    thread.start()
    return thread


@dataclass
class Partial:
    """Something a job shows before it ends (a quick first answer): ``progress.partial(value)``."""

    value: object


def _relay(fn, stop: threading.Event):
    """Run ``fn(progress, should_stop)`` in a helper thread and yield its progress reports
    ``(done, total, label)`` as they arrive; return its result or raise its exception."""
    from napari_ssdpc.errors import Cancelled

    reports: queue.Queue = queue.Queue()
    box = {}

    def progress(done, total, label=""):
        if stop.is_set():
            raise Cancelled("cancelled")
        reports.put((int(done), int(total), str(label)))

    def first_answer(value):
        if stop.is_set():
            raise Cancelled("cancelled")
        reports.put(Partial(value))

    progress.partial = first_answer  # type: ignore[attr-defined]

    def target():
        try:
            box["value"] = fn(progress, stop.is_set)
        except BaseException as e:  # handed to the generator, re-raised there
            box["error"] = e
        finally:
            reports.put(None)

    thread = start_helper(target, "napari-ssdpc job", stop)
    try:
        while (msg := reports.get()) is not None:
            yield msg
    finally:
        if thread.is_alive():  # closed early: stop the core at its next iteration
            stop.set()
        thread.join()
    if "error" in box:
        raise box["error"]
    return box["value"]


def _job(fn, stop):
    """Generator run by the thread_worker: progress reports, then an Outcome."""
    from napari_ssdpc.errors import Cancelled

    try:
        value = yield from _relay(fn, stop)
    except Cancelled:
        return Outcome(cancelled=True)
    except SsdpcError as e:
        return Outcome(error=str(e))
    return Outcome(value=value)


class JobRunner:
    """Run/Cancel buttons, a status line and a napari progress bar around one job at a time."""

    def __init__(self, title: str, run: PushButton, cancel: PushButton, status: Label):
        self.title, self.run_button, self.cancel_button, self.status = title, run, cancel, status
        self.worker = None
        self._stop = None
        self._pbar = None
        self._on_partial = None
        self._shown_at = 0.0
        self._gone = False
        cancel.enabled = False
        cancel.changed.connect(self.cancel)
        status.native.destroyed.connect(self._widget_gone)  # the viewer closed: its jobs stop

    def _widget_gone(self, *_):
        self._gone = True
        if self._stop is not None:
            self._stop.set()

    @property
    def running(self) -> bool:
        """Whether a job is running."""
        return self.worker is not None

    def start(self, fn, on_result, label: str, on_partial=None):
        """Run ``fn`` in a worker with progress and Cancel.

        Parameters
        ----------
        fn : callable
            ``fn(progress, should_stop)``, run in a helper thread; ``progress.partial(value)``
            hands ``value`` to ``on_partial`` while it goes on.
        on_result : callable
            ``on_result(value)`` on the main thread; returns the status text.
        label : str
            Progress-bar title.
        on_partial : callable, optional
            ``on_partial(value)`` on the main thread; returns the status text.

        Returns
        -------
        worker or None
            None when a job is already running.
        """
        if self.running:
            notify.info(f"{self.title} is already running; cancel it first")
            return None
        self._stop = threading.Event()
        self._warned = set()
        self._on_partial = on_partial
        self._pbar = napari_progress(total=0, desc=label)
        self.status.value = f"{label}…"
        self.run_button.enabled = False
        self.cancel_button.enabled = True
        worker = create_worker(_job, fn, self._stop, _start_thread=False)
        worker.yielded.connect(self._on_progress)
        worker.warned.connect(self._on_warning)
        worker.returned.connect(lambda out: self._on_returned(out, on_result))
        worker.aborted.connect(self._on_aborted)
        worker.finished.connect(self._on_finished)
        self.worker = worker
        _room_for_one_more()
        worker.start()
        return worker

    def cancel(self, *_):
        """Ask the running job to stop (within one iteration)."""
        if self._stop is not None:
            self._stop.set()
            self.status.value = "cancelling…"

    def _on_progress(self, msg):
        if self._gone:
            return
        if isinstance(msg, Partial):
            self._show_partial(msg.value)
            return
        done, total, label = msg
        pbar = self._pbar
        now = time.monotonic()
        if pbar is None or (now - self._shown_at < PROGRESS_EVERY_S and done < total):
            return  # a repaint of napari's progress bar costs the GUI thread: a few a second are enough
        self._shown_at = now
        self.status.value = f"{label} {done}/{total}" if total else label
        # napari's progress bar processes events while it repaints: on a turn of its own, so that
        # nothing else that waits is run inside it
        later(partial(self._show_progress, pbar, done, total, label), key=(self, "progress"))

    def _show_progress(self, pbar, done: int, total: int, label: str) -> None:
        if pbar is not self._pbar:  # its job has ended meanwhile: the bar is closed
            return
        if pbar.total != total:
            pbar.total = total
        pbar.set_description(label)
        pbar.update(done - pbar.n)

    def _show_partial(self, value):
        if self._on_partial is None or (self._stop is not None and self._stop.is_set()):
            return
        try:
            msg = self._on_partial(value)
        except SsdpcError as e:
            notify.error(str(e))
        else:
            if msg:
                self.status.value = msg

    def _on_aborted(self):
        """napari's own cancel (worker.quit): stop the core too."""
        if self._stop is not None:
            self._stop.set()
        if not self._gone:
            self.status.value = "cancelled"

    def _on_warning(self, args):
        """A warning raised while the job ran (worker.warned gives showwarning's arguments): core
        warnings become napari warnings, each message once per job."""
        message, category = args[0], args[1]
        if issubclass(category, SsdpcWarning) and str(message) not in self._warned:
            self._warned.add(str(message))
            notify.warning(str(message))

    def _on_returned(self, out: Outcome, on_result):
        if self._gone:
            return
        if out.cancelled:
            self.status.value = "cancelled"
            notify.info(f"{self.title}: cancelled")
        elif out.error is not None:
            self.status.value = f"error: {out.error}"
            notify.error(out.error)
        else:
            try:
                msg = on_result(out.value)
            except SsdpcError as e:
                self.status.value = f"error: {e}"
                notify.error(str(e))
            else:
                self.status.value = msg or "done"

    def _on_finished(self):
        if self._pbar is not None:
            self._pbar.close()
        self._pbar = None
        self.worker = None
        if not self._gone:
            self.run_button.enabled = True
            self.cancel_button.enabled = False
