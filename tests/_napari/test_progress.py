"""Progress from the first second and Cancel, in the menu order (dock, sample, calibrate, build):
the sign probes of 'auto' report against the set iterations and stop on Cancel; a Build made with
the defaults serves Reconstruct, also after the settings just saved are loaded again."""

from __future__ import annotations

import time

import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify
from napari_ssdpc._napari import sample_data as _sample_data


@pytest.fixture
def built(make_napari_viewer, qtbot, monkeypatch):
    """The dock, the bead sample, its optics, a calibration and operators built with the defaults."""
    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer()
    _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    w = {k.lower(): v for k, v in dock.tabs.items()}
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    w["optics"].set_optics(_sample_data.bead_frames()[3])
    w["calibrate"].run()
    _steps.wait_for(qtbot, w["calibrate"])
    op = w["method"]
    op.z_min.value, op.z_max.value, op.sign.value, op.tv_iterations.value = -10.0, 10.0, "auto", 20
    op.run()
    _steps.wait_for(qtbot, op)
    assert shown == [] and "flat 'PMMA bead flat'" in op.status.value  # built with the sample's flat
    yield viewer, dock, w, shown


def _recorded(widget):
    """Progress messages (done, total, label) of the widget's next job, from its first one on (a
    first answer it shows left out)."""
    msgs: list = []
    show = widget.runner._on_progress
    widget.runner._on_progress = lambda msg: (isinstance(msg, tuple) and msgs.append(msg), show(msg))
    return msgs


def test_reconstruct_uses_the_build_and_reports_the_sign_probes(built, qtbot, tmp_path):
    viewer, dock, w, shown = built
    rec = dock.session.built[1]
    w["method"].run()  # nothing changed: nothing is built again
    assert w["method"].runner.worker is None and w["method"].status.value.startswith("up to date")
    assert dock.load_settings(dock.save_settings(tmp_path / "run.yaml"))  # the settings just saved
    msgs = _recorded(w["reconstruct"])
    w["reconstruct"].run()
    _steps.wait_for(qtbot, w["reconstruct"])
    assert shown == [] and dock.session.built[1] is rec  # the operators were kept
    assert not any(label.startswith("operators") for _, _, label in msgs)
    labels = [label for _, _, label in msgs]
    assert labels[0] == "TV: probing the sign (denser)" and "TV: probing the sign (lighter)" in labels
    assert {total for _, total, label in msgs if label.startswith("TV")} == {20}  # the set iterations
    assert "PMMA bead RI" in viewer.layers


def test_cancel_stops_the_sign_probes(built, qtbot):
    viewer, dock, w, shown = built
    w["method"].tv_iterations.value = 500
    rc = w["reconstruct"]
    msgs = _recorded(rc)
    rc.run()
    qtbot.waitUntil(lambda: any("probing" in m[2] for m in msgs), timeout=60_000)
    cancelled = time.perf_counter()
    rc.cancel_button.changed.emit(True)  # the Cancel button
    _steps.wait_for(qtbot, rc)
    assert time.perf_counter() - cancelled < 5.0  # within an iteration, not after 2 x 12 probe iterations
    # the first answer shown before the probes is taken back: no layer is left from a cancelled job
    assert rc.status.value == "cancelled" and "PMMA bead RI" not in viewer.layers
    assert all("probing" in m[2] for m in msgs)  # stopped while probing
