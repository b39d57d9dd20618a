"""Movies of a reconstruction from the dock: a turn in 3D and a time series, through napari-animation."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")
pytest.importorskip("napari_animation")

from napari_ssdpc._napari import notify as _notify
from napari_ssdpc._napari.layers import result_layer
from napari_ssdpc._napari.widgets.movie import MovieWidget


def _bead(t=None):
    z, y, x = np.mgrid[-8:8, -16:16, -16:16]
    v = 1.518 - 0.03 * (x * x + y * y + (2 * z) ** 2 < 100)
    data = v.astype(np.float32) if t is None else np.stack([np.roll(v, k, axis=2) for k in range(t)]).astype(np.float32)
    return result_layer(data, "ri", (2.0, 0.85, 0.85), (-16.0, -13.6, -13.6), name="bead", info={"medium_index": 1.518})


@pytest.mark.parametrize(("kind", "frames", "expected"), [("turn in 3D", None, 4 * 5 + 1), ("time series", 6, 6)])
def test_a_movie_is_written_with_one_image_per_step(make_napari_viewer, tmp_path, monkeypatch, kind, frames, expected):
    from PIL import Image

    shown = []
    monkeypatch.setattr(_notify, "error", lambda msg: shown.append(str(msg)))
    viewer = make_napari_viewer(show=True)  # the canvas renders what the camera sees
    data, kwargs, _ = _bead(frames)
    viewer.add_image(data, **kwargs)
    w = MovieWidget(viewer)
    w.reset_choices()
    w.kind.value, w.seconds.value, w.fps.value = kind, 1, 20  # a turn: 4 key frames of 5 steps
    w.path.value = tmp_path / "bead.gif"
    out = w.export()
    assert shown == [] and out is not None and out.is_file()
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
