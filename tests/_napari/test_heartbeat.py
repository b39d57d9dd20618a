"""The GUI never stalls: a 50 ms timer on napari's event loop while a user goes through the whole
workflow in the menu order (open the dock, open the bead sample, calibrate, reconstruct, draw a
profile, look at the slices, reconstruct a series into a store, export a movie, open the time-series
sample), on a quiet machine and beside a neighbour that keeps every core busy. Quiet: no gap between
two beats may exceed 1 s (skipped where napari itself is too slow on the display to tell). Beside
the neighbour: 1 s, or napari's own longest gap on the same display and load (idle, and adding three
1024 x 1024 images) times 1.5 where that is longer. Every layer box holds the right layer on its
own (docs/napari.md gives the measured waits).

A walk whose longest gap exceeds the bound is walked once more, and each step keeps the shorter of
its two longest gaps: the plugin's work on the GUI thread stalls every walk alike, while a one-off
pause of a shared machine (CI once measured 1.41 s at the end of Calibrate where a quiet run
measures 0.42-0.72 s) rarely hits the same step twice. The second walk finds the first's imports
and caches warm: a first-use cost on the GUI thread fails the first walk, and passes only if the
rest of that step then fits the bound."""

from __future__ import annotations

import os
import time

import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify

BEAT_MS = 50
MAX_STALL_S = 1.0  # a quiet 2-core machine measures 0.1-0.6 s a step, beside the neighbour 0.2-0.8 s (docs/napari.md)
#: The bound where napari's own stall adding three 1024 x 1024 images (what opening a sample costs
#: it) is longer than the plugin's bound would allow: this many times napari's own.
OVER_NAPARI = 1.5
#: On a quiet machine napari alone adding those images took 0.4 s where the 1 s bound was set; a
#: display that makes napari itself slower than this cannot tell the plugin's stalls from its own:
#: the quiet test says so and skips (docs/napari.md).
REFERENCE_MAX_S = 0.6


def _busy() -> str:
    """Why the wall-clock gaps would measure other jobs, not the GUI: '' on a machine that is not
    loaded beyond its cores."""
    load, cores = os.getloadavg()[0], os.cpu_count() or 1
    return f"the machine is busy (load {load:.1f} on {cores} cores)" if load > cores else ""


@pytest.fixture
def busy_neighbour():
    """A process per core spinning for as long as the test runs (and no longer than the test's own
    process: a spinner ends when its parent has gone)."""
    import subprocess
    import sys

    spin = f"import os\nwhile os.getppid() == {os.getpid()}: pass"
    spinners = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(os.cpu_count() or 1)]
    time.sleep(1.0)  # every core busy before the walk starts
    yield len(spinners)
    for p in spinners:
        p.kill()
        p.wait()


def _walk_twice_if_over(walk, tmp_path):
    """Walk; where a step's longest gap exceeds the bound, walk again and keep each step's shorter
    longest gap. Asserts every step within the bound."""
    gaps, bound = walk(tmp_path / "first")
    if max(gaps.values()) >= bound:
        again, bound_again = walk(tmp_path / "again")
        print("walked again: the first walk's longest gaps", {k: round(v, 2) for k, v in gaps.items()})
        gaps = {k: min(v, again.get(k, v)) for k, v in gaps.items()}
        bound = max(bound, bound_again)
    assert max(gaps.values()) < bound, {k: round(v, 2) for k, v in gaps.items()}


@pytest.mark.skipif(bool(_busy()), reason=_busy() or "-")
def test_the_event_loop_keeps_beating_through_the_whole_workflow(make_napari_viewer, qtbot, monkeypatch, tmp_path):
    _walk_twice_if_over(
        lambda folder: _walk(make_napari_viewer, qtbot, monkeypatch, folder, skip_slow_display=True), tmp_path
    )


def test_the_event_loop_keeps_beating_beside_a_neighbour_that_keeps_every_core_busy(
    make_napari_viewer, qtbot, monkeypatch, tmp_path, busy_neighbour
):
    _walk_twice_if_over(lambda folder: _walk(make_napari_viewer, qtbot, monkeypatch, folder), tmp_path)


def _walk(make_napari_viewer, qtbot, monkeypatch, tmp_path, skip_slow_display=False):
    """One walk through the workflow in a new viewer; returns the longest gap per step (s) and
    the bound (s)."""
    import numpy as np
    from qtpy.QtCore import QTimer

    from napari_ssdpc._napari import sample_data

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    tmp_path.mkdir(parents=True, exist_ok=True)
    monkeypatch.setenv("NAPARI_SSDPC_CONFIG", str(tmp_path))  # nothing remembered from other tests
    viewer = make_napari_viewer(show=True)
    # napari's own one-time set-up of physical units (pint's registry, 0.8 s on a quiet 2-core machine)
    # happens with the first layer in µm, whoever adds it: done here, so the beat measures the plugin
    from napari.utils._units import get_unit_registry

    get_unit_registry().um  # noqa: B018
    beats, step = [], ["idle"]
    timer = QTimer()
    timer.timeout.connect(lambda: beats.append((time.perf_counter(), step[0])))
    timer.start(BEAT_MS)
    qtbot.wait(1500)  # napari doing nothing: what the display and the load alone cost a beat
    out = {}

    def napari_alone():
        for i in range(3):
            viewer.add_image(np.zeros((1024, 1024), np.uint16), name=f"reference {i}")

    step[0] = "napari alone"
    QTimer.singleShot(0, napari_alone)
    qtbot.wait(800)
    # napari's own stall may outlast the wait: the beat that ends it still belongs to "napari alone"
    qtbot.waitUntil(lambda: "reference 2" in viewer.layers, timeout=20000)
    n = len(beats)
    qtbot.waitUntil(lambda: len(beats) > n + 1, timeout=20000)
    step[0] = "idle"
    # napari's own: adding the images, or doing nothing at all on a loaded machine
    reference = max(
        (t1 - t0 for (t0, _), (t1, n) in zip(beats, beats[1:]) if n in ("napari alone", "idle")), default=0.0
    )
    for i in range(3):
        viewer.layers.remove(f"reference {i}")
    qtbot.wait(300)
    if skip_slow_display and reference > REFERENCE_MAX_S:
        timer.stop()
        pytest.skip(
            f"napari itself stalls {reference:.2f} s on this display (at most {REFERENCE_MAX_S} s for the "
            f"{MAX_STALL_S} s bound): too slow to measure the plugin's stalls"
        )
    bound = MAX_STALL_S if skip_slow_display else max(MAX_STALL_S, OVER_NAPARI * reference)
    print(f"napari alone (idle, three 1024 x 1024 images): longest gap {reference:.2f} s; the bound {bound:.2f} s")

    def run(name, action, widget=None, settle_ms=500):
        step[0] = name
        QTimer.singleShot(0, action)  # as a menu action or a click: from the event loop
        qtbot.wait(50)
        if widget is not None:
            _steps.wait_for(qtbot, widget)
        _steps.wait_for_turns(qtbot)
        qtbot.wait(settle_ms)

    run("open the dock", lambda: out.update(dock=viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")[1]))
    tabs = out["dock"].tabs
    calibrate, method, rec, profile, slices, movie = (
        tabs[k] for k in ("Calibrate", "Method", "Reconstruct", "Profile", "Slices", "Movie")
    )
    run("open the sample", lambda: viewer.open_sample("napari-ssdpc", "pmma_bead"))
    assert calibrate.image.value.name == "PMMA bead white"
    run("calibrate", calibrate.run, calibrate, settle_ms=1000)
    assert "PMMA bead white EI circles" in viewer.layers
    # the defaults the data chose: the raw frame, its flat, the calibration just made
    assert (rec.raw.value.name, rec.flat.value.name) == ("PMMA bead", "PMMA bead flat")
    assert method.calibration.value.name == "PMMA bead white EI circles"
    method.z_min.value, method.z_max.value, method.dz.value = -10.0, 10.0, 2.0  # 11 planes: a short test
    method.tv_iterations.value = 10
    run("reconstruct", rec.run, rec)
    assert profile.image.value.name == slices.layer.value.name == movie.layer.value.name == "PMMA bead RI"

    def draw_profile():
        lines = profile.new_line_layer()
        lines.add_lines(np.array([[5.0, 40.0, 20.0], [5.0, 40.0, 100.0]]))  # across the bead, in voxels

    run("draw a profile", draw_profile)
    assert len(profile.profiles) == 1
    run("look at the slices", slices.update)
    assert slices.info.value.startswith("through z")
    raw = viewer.layers["PMMA bead"]  # a two-frame recording of it, in µm as the sample's frames
    series = viewer.add_image(
        np.stack([raw.data, raw.data]), name="bead series", axis_labels=("t", "y", "x"),
        scale=(1.0, *raw.scale), translate=(0.0, *raw.translate), units=("second", *raw.units),
    )  # fmt: skip
    rec.raw.value, rec.frames.value, rec.store.value = series, "all frames", tmp_path / "series.zarr"
    run("reconstruct a series", rec.run, rec)
    assert viewer.layers["series RI"].data.shape[:2] == (2, 11)
    movie.layer.value = viewer.layers["PMMA bead RI"]
    movie.seconds.value, movie.fps.value, movie.path.value = 1, 8, tmp_path / "bead.gif"
    run("export a movie", movie.export, movie)
    assert (tmp_path / "bead.gif").is_file(), (movie.status.value, shown)
    # last, as a user trying the other sample: it opens from its shipped frames (the thread that
    # simulates the others is left out: it would outlive the test)
    monkeypatch.setattr(sample_data, "SeriesPrefetch", lambda n: None)
    run("open the time-series sample", lambda: viewer.open_sample("napari-ssdpc", "moving_sample"))
    assert viewer.layers["moving sample"].data.shape[0] == sample_data.SERIES_FRAMES
    timer.stop()
    assert shown == []
    gaps = {}
    for (t0, _), (t1, name) in zip(beats, beats[1:]):
        if name not in ("napari alone", "idle"):
            gaps[name] = max(gaps.get(name, 0.0), t1 - t0)
    print("longest gap between beats per step, s:", {k: round(v, 2) for k, v in gaps.items()})
    steps = {"open the dock", "open the sample", "calibrate", "reconstruct", "draw a profile", "look at the slices"}
    assert set(gaps) >= steps | {"open the time-series sample", "reconstruct a series", "export a movie"}
    viewer.close()
    return gaps, bound
