"""The workflow as a user meets it: every widget opened from napari's Plugins menu.

napari hands each plugin dock widget its own proxy of the viewer. The widgets must still share
one session: the optics set in one, the calibration made in another and the reconstruction in a
third.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify
from napari_ssdpc._napari import sample_data as _sample_data
from napari_ssdpc._napari import widgets as _widgets

Z, DZ = (-10.0, 10.0), 2.0
MENU = ("1. Optics", "2. Calibrate", "3. Operators", "4. Reconstruct", "5. Line profile")


def test_widgets_opened_from_the_plugins_menu_share_one_session_and_reach_an_ri_volume(
    make_napari_viewer, qtbot, monkeypatch
):
    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer()
    w = {}
    for name in MENU:
        _, widget = viewer.window.add_plugin_dock_widget("napari-ssdpc", name)
        w[name.split(". ")[1].lower()] = widget
    sessions = {id(x.session) for x in w.values() if hasattr(x, "session")}
    assert len(sessions) == 1  # one model for the viewer, whatever proxy each widget was given
    assert next(iter(w.values())).session is _widgets.session_for(viewer)

    frame, flat, white, optics = _sample_data.bead_frames()
    _steps.prepare_bead(viewer, qtbot, w, optics, Z, DZ)  # the optics are set in Optics, read by the others
    assert _widgets.session_for(viewer).optics is w["calibrate"].session.optics
    w["operators"].sign.value, w["operators"].tv_iterations.value = "lighter", 30  # PMMA in oil: lighter
    w["reconstruct"].run()
    _steps.wait_for(qtbot, w["reconstruct"])
    assert shown == []
    ri = viewer.layers["PMMA bead (raw light field) RI"]
    assert ri.data.shape[0] == 11 and np.allclose(ri.scale[0], DZ)
    settings = ri.metadata["ssdpc"]["settings"]
    assert settings["method"] == "tv" and settings["tv_sign"] == "lighter" and settings["tv_iterations_run"] <= 30
    assert ri.data.max() <= optics.medium_index + 1e-6  # the sign constraint holds: nowhere denser
    assert np.allclose(ri.scale[1:], optics.object_pixel_um, rtol=2e-3)
    # the bead (n 1.49 in 1.518) at the world origin: Δn < 0 there
    zc, yc, xc = np.round(ri.world_to_data((0.0, 0.0, 0.0))).astype(int)
    assert ri.data[zc, yc, xc] - optics.medium_index < -0.002
