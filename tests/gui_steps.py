"""Shared steps of the napari GUI tests: wait for a widget's job, wire the bead workflow.

Imported by the tests as ``gui_steps`` (``tests/`` is on the test path, see pyproject.toml).
"""

from __future__ import annotations

WORKER_TIMEOUT_MS = 180_000


def wait_for(qtbot, widget):
    """Wait until the widget's running job has finished."""
    worker = widget.runner.worker
    if worker is not None:
        with qtbot.waitSignal(worker.finished, timeout=WORKER_TIMEOUT_MS):
            pass
    qtbot.waitUntil(lambda: widget.runner.worker is None, timeout=5000)


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
