"""Jobs start at once, however many run: napari's workers share Qt's global thread pool, which has
as many threads as cores, and on 2 cores a third job (a movie beside a followed recording and a
reconstruction) waited, unseen, for one of the others to end."""

from __future__ import annotations

import threading

import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

from napari_ssdpc._napari.widgets.jobs import JobRunner


@pytest.fixture
def two_thread_pool():
    """Qt's global pool as on a 2-core machine (restored after)."""
    from qtpy.QtCore import QThreadPool

    pool = QThreadPool.globalInstance()
    before = pool.maxThreadCount()
    pool.setMaxThreadCount(2)
    yield pool
    pool.setMaxThreadCount(before)


def test_three_jobs_at_once_all_start_at_once(qtbot, two_thread_pool):
    from magicgui.widgets import Label, PushButton

    release, started = threading.Event(), []
    runners = [JobRunner(f"job {i}", PushButton(), PushButton(), Label()) for i in range(3)]

    def work(progress, should_stop, i):
        started.append(i)
        release.wait(30.0)
        return i

    for i, runner in enumerate(runners):
        assert runner.start(lambda p, s, i=i: work(p, s, i), lambda v: f"job {v} done", f"job {i}") is not None
    try:
        qtbot.waitUntil(lambda: len(started) == 3, timeout=10_000)  # not after one of the others
    finally:
        release.set()
    qtbot.waitUntil(lambda: all(r.worker is None for r in runners), timeout=10_000)
    assert sorted(started) == [0, 1, 2] and [r.status.value for r in runners] == [f"job {i} done" for i in range(3)]
