"""The bead sample ships with the package, so it opens at once, and it is what the simulator makes."""

from __future__ import annotations

import time

import numpy as np
import pytest

from napari_ssdpc._napari import sample_data


def test_the_bead_sample_opens_from_the_shipped_frames_without_simulating(tmp_path, monkeypatch):
    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path))  # an empty cache: nothing made here before
    t0 = time.perf_counter()
    layers = sample_data.pmma_bead_sample()
    seconds = time.perf_counter() - t0
    assert [kw["name"] for _, kw, _ in layers] == ["PMMA bead white", "PMMA bead flat", "PMMA bead"]
    assert all(d.shape == (sample_data.BEAD_ROI_PX,) * 2 and d.dtype == np.uint16 for d, _, _ in layers)
    assert not list(tmp_path.rglob("*.tif"))  # read from the package, not simulated into the cache
    print(f"bead sample opened in {seconds:.2f} s")


@pytest.mark.slow
def test_the_shipped_bead_frames_are_what_the_simulator_makes_now(tmp_path, monkeypatch):
    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(sample_data, "SHIPPED", tmp_path / "none")  # simulate, do not read the shipped ones
    made = sample_data.bead_frames()[:3]
    monkeypatch.setattr(sample_data, "SHIPPED", sample_data.Path(sample_data.__file__).parent / "data")
    monkeypatch.setenv("NAPARI_SSDPC_CACHE", str(tmp_path / "empty"))
    shipped = sample_data.bead_frames()[:3]
    for a, b in zip(made, shipped):
        np.testing.assert_array_equal(a, b)
