"""napari exits cleanly with work still running in the background: the time-series sample's
simulation and a reconstruction job stop within a step when the interpreter exits (left running,
they were torn down inside an FFT and the exit aborted: "terminate called without an active
exception", rc 134)."""

from __future__ import annotations

import threading
import time

import pytest

pytest.importorskip("napari")

from napari_ssdpc._napari import sample_cache, sample_data
from napari_ssdpc._napari.widgets import jobs


def test_the_series_simulation_stops_within_a_source_point_at_exit(monkeypatch):
    started = threading.Event()

    def slow_frame(i, n):  # a frame of many source points, each ending with the progress callback
        started.set()
        while True:
            time.sleep(0.01)
            sample_cache.unless_exiting(0, 1)

    monkeypatch.setattr(sample_data, "series_frame", slow_frame)
    monkeypatch.setattr(sample_cache, "BACKGROUND", [])
    prefetch = sample_data.SeriesPrefetch(3)
    assert started.wait(5.0)
    try:
        t0 = time.perf_counter()
        sample_cache.stop_background()  # what atexit runs
        assert not prefetch.thread.is_alive() and time.perf_counter() - t0 < 1.0
        assert prefetch.made == set()  # nothing cached from a cut simulation
    finally:
        sample_cache.EXITING.clear()


def test_a_running_job_is_stopped_and_joined_at_exit():
    stop = threading.Event()
    steps = []

    def job(progress, should_stop):
        progress(0, 1, "running")
        while not should_stop():
            steps.append(1)
            time.sleep(0.01)
        return "stopped"

    relay = jobs._relay(job, stop)
    assert next(relay) == (0, 1, "running")  # the job runs in its thread
    while not steps:
        time.sleep(0.01)
    [(thread, flag)] = [r for r in jobs._RUNNING if r[1] is stop]
    t0 = time.perf_counter()
    jobs._stop_jobs()  # what atexit runs
    assert flag.is_set() and not thread.is_alive() and time.perf_counter() - t0 < 1.0
    with pytest.raises(StopIteration) as ended:
        next(relay)
    assert ended.value.value == "stopped"
