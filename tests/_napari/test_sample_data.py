"""The bead sample ships with the package, so it opens at once, and it is what the simulator makes."""

from __future__ import annotations

import time

import numpy as np
import pytest

from napari_ssdpc._napari import sample_cache, sample_data


def test_the_bead_sample_opens_from_the_shipped_frames_without_simulating(tmp_path, monkeypatch):
    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path))  # an empty cache: nothing made here before
    t0 = time.perf_counter()
    layers = sample_data.pmma_bead_sample()
    seconds = time.perf_counter() - t0
    assert [kw["name"] for _, kw, _ in layers] == ["PMMA bead white", "PMMA bead flat", "PMMA bead"]
    assert all(d.shape == (sample_data.BEAD_ROI_PX,) * 2 and d.dtype == np.uint16 for d, _, _ in layers)
    assert not list(tmp_path.rglob("*.tif"))  # read from the package, not simulated into the cache
    print(f"bead sample opened in {seconds:.2f} s")


def test_the_series_sample_opens_and_shows_its_first_frame_without_simulating(tmp_path, monkeypatch):
    """Its flat, white and first frames ship: nothing is simulated on napari's thread when it opens
    (an empty cache simulated the flat and white frames there: 127 s of frozen GUI on a busy machine)."""
    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path))
    white, flat, series = (d for d, _, _ in sample_data.moving_sample_series(prefetch=False))
    first = np.asarray(series[0])
    assert white.shape == flat.shape == first.shape == (sample_data.BEAD_ROI_PX,) * 2
    assert not list(tmp_path.rglob("*.tif"))  # read from the package, not simulated into the cache
    assert sample_data.series_optics().condenser_na == 0.3  # phase contrast (NA 0.1: four lenslets carry it)


@pytest.mark.slow
def test_the_shipped_frames_are_what_the_simulator_makes_now(tmp_path, monkeypatch):
    def frames():
        return [*sample_data.bead_frames()[:3], *sample_data.series_flat_white(), sample_data.series_frame(0)]

    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(sample_cache, "SHIPPED", tmp_path / "none")  # simulate, do not read the shipped ones
    made = frames()
    monkeypatch.setattr(sample_cache, "SHIPPED", sample_cache.Path(sample_cache.__file__).parent / "data")
    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path / "empty"))
    shipped = frames()
    assert not list((tmp_path / "empty").rglob("*.tif"))
    for a, b in zip(made, shipped, strict=True):
        np.testing.assert_array_equal(a, b)
