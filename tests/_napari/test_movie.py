"""Movies of a reconstruction from the dock: a turn in 3D and a time series, through napari-animation,
written as a job with progress and Cancel; the view is restored afterwards, also on Cancel or an error."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")
pytest.importorskip("napari_animation")

import gui_steps as _steps
from napari_ssdpc._napari import notify as _notify
from napari_ssdpc._napari.layers import result_layer
from napari_ssdpc._napari.widgets.movie import MovieWidget, camera_of


def _bead(t=None):
    z, y, x = np.mgrid[-8:8, -16:16, -16:16]
    v = 1.518 - 0.03 * (x * x + y * y + (2 * z) ** 2 < 100)
    data = v.astype(np.float32) if t is None else np.stack([np.roll(v, k, axis=2) for k in range(t)]).astype(np.float32)
    return result_layer(data, "ri", (2.0, 0.85, 0.85), (-16.0, -13.6, -13.6), name="bead", info={"medium_index": 1.518})


def _view(viewer):
    """What the export must leave as it found it."""
    cam = camera_of(viewer)
    return (
        viewer.dims.ndisplay,
        tuple(viewer.dims.current_step),
        tuple(np.round(cam.center, 6)),
        round(cam.zoom, 6),
        tuple(np.round(cam.angles, 6)),
        tuple(layer.visible for layer in viewer.layers),
    )


@pytest.mark.parametrize(("kind", "frames", "expected"), [("turn in 3D", None, 4 * 5 + 1), ("time series", 6, 6)])
def test_a_movie_is_written_with_one_image_per_step(
    make_napari_viewer, qtbot, tmp_path, monkeypatch, kind, frames, expected
):
    from PIL import Image

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer(show=True)  # the canvas renders what the camera sees
    data, kwargs, _ = _bead(frames)
    viewer.add_image(data, **kwargs)
    w = MovieWidget(viewer)
    w.reset_choices()
    w.kind.value, w.seconds.value, w.fps.value = kind, 1, 20  # a turn: 4 key frames of 5 steps
    w.path.value = out = tmp_path / "bead.gif"
    view = _view(viewer)
    assert w.export() is not None
    _steps.wait_for(qtbot, w)
    assert shown == [] and out.is_file() and w.status.value == "wrote bead.gif"
    assert _view(viewer) == view  # the camera, 2D/3D and the visible layers as before
    with Image.open(out) as movie:
        assert movie.n_frames == expected  # one image per interpolation step
        assert np.ptp(np.asarray(movie.convert("L"))) > 0  # the bead shows: not an empty canvas


def test_a_movie_needs_a_volume_and_a_file_name(make_napari_viewer, tmp_path, monkeypatch):
    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer()
    w = MovieWidget(viewer)
    assert w.export() is None and "reconstruct a frame first" in shown[-1]
    data, kwargs, _ = _bead()
    viewer.add_image(data, **kwargs)
    w.reset_choices()
    w.kind.value, w.path.value = "time series", tmp_path / "bead.gif"
    assert w.export() is None and "has no time axis" in shown[-1]
    w.kind.value, w.path.value = "turn in 3D", tmp_path / "bead.avi"
    assert w.export() is None and ".mp4 or .gif" in shown[-1]


def test_cancel_stops_the_movie_leaves_no_file_and_restores_the_view(make_napari_viewer, qtbot, tmp_path, monkeypatch):
    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer(show=True)
    data, kwargs, _ = _bead()
    viewer.add_image(data, **kwargs)
    viewer.add_image(data[0], name="other")
    camera_of(viewer).zoom, camera_of(viewer).center = 3.0, (0.0, 2.0, 1.0)
    view = _view(viewer)
    w = MovieWidget(viewer)
    w.reset_choices()
    w.layer.value = viewer.layers["bead RI"]
    w.kind.value, w.seconds.value, w.fps.value = "turn in 3D", 30, 20  # 601 images: long enough to cancel
    w.path.value = out = tmp_path / "long.gif"
    worker = w.export()
    assert worker is not None and w.cancel_button.enabled
    qtbot.waitUntil(lambda: "movie frames" in w.status.value, timeout=30_000)  # progress from the first frames
    w.cancel_button.native.click()
    _steps.wait_for(qtbot, w)
    assert shown == [] and w.status.value == "cancelled" and not out.exists()
    assert _view(viewer) == view

    # a file that cannot be written: one line naming it, the view restored
    w.seconds.value, w.path.value = 1, tmp_path / "missing" / "bead.gif"
    w.export()
    _steps.wait_for(qtbot, w)
    assert len(shown) == 1 and "bead.gif" in shown[0] and w.status.value.startswith("error:")
    assert _view(viewer) == view


def test_a_frame_that_fails_to_render_stops_the_movie_with_one_line(make_napari_viewer, qtbot, tmp_path, monkeypatch):
    from napari_ssdpc._napari.widgets import movie

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    render = movie.render_frame

    def failing(animation, i):  # the canvas fails at the fourth frame (a lost OpenGL context, say)
        if i == 3:
            raise RuntimeError("no OpenGL context")
        return render(animation, i)

    monkeypatch.setattr(movie, "render_frame", failing)
    viewer = make_napari_viewer(show=True)
    data, kwargs, _ = _bead()
    viewer.add_image(data, **kwargs)
    view = _view(viewer)
    w = MovieWidget(viewer)
    w.reset_choices()
    w.kind.value, w.seconds.value, w.fps.value = "turn in 3D", 1, 20
    w.path.value = out = tmp_path / "bead.gif"
    start = time.monotonic()
    w.export()
    _steps.wait_for(qtbot, w)
    assert time.monotonic() - start < 20 and not out.exists() and _view(viewer) == view
    assert shown == ["movie frame 4 could not be rendered (RuntimeError: no OpenGL context); export again"]
