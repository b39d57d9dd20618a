"""Shared steps of the napari GUI tests: wait for a widget's job, wire the bead workflow.

Imported by the tests as ``gui_steps`` (``tests/`` is on the test path, see pyproject.toml).
"""

from __future__ import annotations

WORKER_TIMEOUT_MS = 180_000


def wait_for(qtbot, widget):
    """Wait until the widget's running job has finished and what it shows is all shown (layers and
    plots come one per turn of the event loop)."""
    worker = widget.runner.worker
    if worker is not None:
        with qtbot.waitSignal(worker.finished, timeout=WORKER_TIMEOUT_MS):
            pass
    qtbot.waitUntil(lambda: widget.runner.worker is None, timeout=5000)
    wait_for_turns(qtbot)


def wait_for_turns(qtbot):
    """Wait until what waits for a turn of the event loop of its own is all done (the layers of a
    sample, a job or a store, the plots)."""
    from napari_ssdpc._napari import turns

    qtbot.waitUntil(lambda: turns.pending() == 0, timeout=10_000)


def prepare_bead(viewer, qtbot, widgets, optics, z, dz):
    """Sample bead layers in, optics set, calibrated on the white frame, z grid and inputs chosen.

    ``widgets`` maps 'optics', 'calibrate', 'operators', 'reconstruct' to the widgets.
    """
    from napari_ssdpc._napari import sample_data

    for data, kw, kind in sample_data.pmma_bead_sample():
        getattr(viewer, f"add_{kind}")(data, **kw)
    widgets["optics"].set_optics(optics)
    widgets["calibrate"].image.value = viewer.layers["PMMA bead white"]
    widgets["calibrate"].run()
    wait_for(qtbot, widgets["calibrate"])
    op = widgets["operators"]
    op.calibration.value = viewer.layers["PMMA bead white EI circles"]
    op.z_min.value, op.z_max.value, op.dz.value = z[0], z[1], dz
    rc = widgets["reconstruct"]
    rc.raw.value = viewer.layers["PMMA bead"]
    rc.flat.value = viewer.layers["PMMA bead flat"]
    return widgets


def live_bead_dock(make_napari_viewer, qtbot, monkeypatch, n_frames, z=(-10.0, 10.0), dz=5.0):
    """The dock ready to reconstruct the sample bead live (a coarse grid, 'tv' with 5 iterations),
    and ``n_frames`` camera frames of it, each with its own 1 % noise (every volume differs).

    Returns
    -------
    viewer, widgets (by lower-case tab name, 'operators' too), frames (n, H, W) uint16, shown
    (the error messages the plugin showed)
    """
    import numpy as np

    from napari_ssdpc._napari import notify, sample_data

    shown: list[str] = []
    monkeypatch.setattr(notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer()
    _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    w = {k.lower(): v for k, v in dock.tabs.items()}
    w["operators"] = w["method"]
    frame, _, _, optics = sample_data.bead_frames()
    prepare_bead(viewer, qtbot, w, optics, z, dz)
    w["operators"].sign.value, w["operators"].tv_iterations.value = "lighter", 5
    rng = np.random.default_rng(0)
    frames = np.stack([(frame * rng.normal(1.0, 0.01, frame.shape)).astype(frame.dtype) for _ in range(n_frames)])
    return viewer, w, frames, shown
