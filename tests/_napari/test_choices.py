"""Layer choices follow the data, in the menu order: the dock is open before the sample arrives.

Every combo box of layers shows the preferred layer after each change of the layer list (raw: the
frame that is neither white nor flat; flat: the flat of the same recording; calibration: the
newest; profile, slices, movie: the newest RI), unless the user picked one that is still there.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify
from napari_ssdpc._napari.layers import calibration_layers, result_layer


@pytest.fixture
def dock(make_napari_viewer, monkeypatch):
    """The ssDPC dock opened from the Plugins menu on an empty viewer; its tabs by lower-case title."""
    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer()
    _, widget = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    tabs = {k.lower(): v for k, v in widget.tabs.items()}
    yield viewer, tabs
    assert shown == []


def _ri(viewer, name: str, value: float):
    data, kwargs, _ = result_layer(
        np.full((3, 8, 8), value, np.float32), "ri", (2.0, 1.0, 1.0), (0.0, 0.0, 0.0), name=name, info={}
    )
    return viewer.add_image(data, **kwargs)


def test_the_sample_opened_after_the_dock_gives_the_raw_flat_and_white_defaults(dock, qtbot):
    viewer, w = dock
    assert w["reconstruct"].raw.value is None and w["calibrate"].image.value is None
    viewer.open_sample("napari-ssdpc", "pmma_bead")  # the bead frame, then its flat and white
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    assert w["calibrate"].image.value.name == "PMMA bead white"
    assert w["reconstruct"].raw.value.name == "PMMA bead"
    assert w["reconstruct"].flat.value.name == "PMMA bead flat"


def test_the_flat_follows_the_recording_of_the_raw_frame(dock, qtbot):
    viewer, w = dock
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    rc = w["reconstruct"]
    # a second recording of another camera region: its flat only fits its own frames
    viewer.add_image(np.ones((64, 80), np.uint16), name="cells flat")
    assert rc.flat.value.name == "PMMA bead flat"  # the raw frame is still the bead's
    viewer.add_image(np.ones((64, 80), np.uint16), name="cells")
    assert rc.raw.value.name == "cells" and rc.flat.value.name == "cells flat"
    rc.raw.value = viewer.layers["PMMA bead"]  # the user goes back to the bead
    assert rc.flat.value.name == "PMMA bead flat"
    viewer.add_image(np.ones((64, 80), np.uint16), name="cells 2")
    assert rc.raw.value.name == "PMMA bead"  # the user's pick stays while it exists


def test_the_users_flat_choice_stays_until_its_layer_goes(dock, qtbot):
    viewer, w = dock
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    rc = w["reconstruct"]
    rc.flat.value = None  # "none (model)" chosen on purpose
    viewer.add_image(np.ones((1024, 1024), np.uint16), name="PMMA bead flat 2")
    assert rc.flat.value is None and rc.flat.picked
    rc.flat.value = viewer.layers["PMMA bead flat 2"]
    viewer.layers.remove("PMMA bead flat 2")
    assert rc.flat.value.name == "PMMA bead flat" and not rc.flat.picked


def test_method_takes_the_newest_calibration(dock, qtbot):
    viewer, w = dock
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    w["calibrate"].run()
    _steps.wait_for(qtbot, w["calibrate"])
    assert w["method"].calibration.value.name == "PMMA bead white EI circles"
    cal = w["calibrate"].calibration
    for data, kwargs, kind in calibration_layers(cal, "second sample white"):  # a second sample, calibrated
        getattr(viewer, f"add_{kind}")(data, **kwargs)
    assert w["method"].calibration.value.name == "second sample white EI circles"
    w["method"].calibration.value = viewer.layers["PMMA bead white EI circles"]  # picked: stays
    for data, kwargs, kind in calibration_layers(cal, "third"):
        getattr(viewer, f"add_{kind}")(data, **kwargs)
    assert w["method"].calibration.value.name == "PMMA bead white EI circles"


def test_profile_slices_and_movie_follow_the_newest_ri(dock, qtbot):
    viewer, w = dock
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    _steps.wait_for_turns(qtbot)  # its flat and white frames come on turns of their own
    assert w["profile"].image.value.name == "PMMA bead"  # no result yet: a frame
    _ri(viewer, "first", 1.5)
    for tab in ("profile", "slices", "movie"):
        box = w[tab].image if tab == "profile" else w[tab].layer
        assert box.value.name == "first RI", tab
    _ri(viewer, "second", 1.5)
    assert w["profile"].image.value.name == "second RI"
    assert w["slices"].layer.value.name == "second RI" and w["movie"].layer.value.name == "second RI"
    w["slices"].layer.value = viewer.layers["first RI"]
    _ri(viewer, "third", 1.5)
    assert w["slices"].layer.value.name == "first RI" and w["profile"].image.value.name == "third RI"
