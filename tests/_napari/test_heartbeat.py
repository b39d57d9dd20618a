"""The GUI never stalls: a 50 ms timer on napari's event loop while a user opens the dock, opens the
sample and calibrates (in the menu order); no gap between two beats may exceed 1 s (docs/napari.md
gives the measured waits)."""

from __future__ import annotations

import os
import time

import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify

BEAT_MS = 50
MAX_STALL_S = 1.0  # generous for a CI machine; a quiet 2-core machine measures about 0.7 s (docs/napari.md)


def _busy() -> str:
    """Why the wall-clock gaps would measure other jobs, not the GUI: '' on a machine that is not
    loaded beyond its cores."""
    load, cores = os.getloadavg()[0], os.cpu_count() or 1
    return f"the machine is busy (load {load:.1f} on {cores} cores)" if load > cores else ""


@pytest.mark.skipif(bool(_busy()), reason=_busy() or "-")
def test_the_event_loop_keeps_beating_through_dock_sample_and_calibrate(make_napari_viewer, qtbot, monkeypatch):
    from qtpy.QtCore import QTimer

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer(show=True)
    # napari's own one-time set-up of physical units (pint's registry, 0.8 s on a quiet 2-core machine)
    # happens with the first layer in µm, whoever adds it: done here, so the beat measures the plugin
    from napari.utils._units import get_unit_registry

    get_unit_registry().um  # noqa: B018
    beats, step = [], ["idle"]
    timer = QTimer()
    timer.timeout.connect(lambda: beats.append((time.perf_counter(), step[0])))
    timer.start(BEAT_MS)
    qtbot.wait(300)
    out = {}

    def run(name, action, settle_ms=500):
        step[0] = name
        QTimer.singleShot(0, action)  # as a menu action: from the event loop
        qtbot.wait(settle_ms)

    run("open the dock", lambda: out.update(dock=viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")[1]))
    run("open the sample", lambda: viewer.open_sample("napari-ssdpc", "pmma_bead"))
    calibrate = out["dock"].tabs["Calibrate"]
    run("calibrate", calibrate.run, settle_ms=50)
    _steps.wait_for(qtbot, calibrate)
    qtbot.wait(1000)  # the calibration's layers drawn
    timer.stop()
    assert shown == [] and "PMMA bead white EI circles" in viewer.layers
    gaps = {}
    for (t0, _), (t1, name) in zip(beats, beats[1:]):
        gaps[name] = max(gaps.get(name, 0.0), t1 - t0)
    assert set(gaps) >= {"open the dock", "open the sample", "calibrate"}
    assert max(gaps.values()) < MAX_STALL_S, {k: round(v, 2) for k, v in gaps.items()}
