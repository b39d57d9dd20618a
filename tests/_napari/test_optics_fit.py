"""The Calibrate tab's "Fit the optics" step on the bead sample: the condenser's NA and centre fitted
to its flat frame, the fitted calibration shown and taken by the Method tab, the report in the tab."""

import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify


def test_fit_the_optics_in_the_calibrate_tab(make_napari_viewer, qtbot, monkeypatch, tmp_path):
    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    monkeypatch.setenv("NAPARI_SSDPC_CONFIG", str(tmp_path))
    viewer = make_napari_viewer()
    dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")[1]
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    calibrate, method = dock.tabs["Calibrate"], dock.tabs["Method"]
    calibrate.run()
    _steps.wait_for(qtbot, calibrate)
    fit = calibrate.fit
    assert fit.flat.value.name == "PMMA bead flat" and fit.white.value.name == "PMMA bead white"
    assert fit.calibration.value.name == "PMMA bead white EI circles"
    assert fit.beads.value is None  # the pupil is fitted to beads only when asked (minutes)
    fit.run()
    _steps.wait_for(qtbot, fit)
    assert shown == [], shown
    assert "PMMA bead white fitted EI circles" in viewer.layers
    assert method.calibration.value.name == "PMMA bead white fitted EI circles"  # the newest: the fitted one
    from napari_ssdpc._napari.widgets.session import calibration_of

    fitted = calibration_of(viewer.layers["PMMA bead white fitted EI circles"])
    # the sample's flat is simulated at the sample optics' condenser: NA 0.3 on axis
    assert fitted.optics.condenser_na == pytest.approx(0.3, abs=0.003)
    assert max(map(abs, fitted.optics.aberrations.condenser_offset_na)) < 0.003
    assert "condenser NA 0.30" in fit.result.value and "view defocus" in fit.result.value
