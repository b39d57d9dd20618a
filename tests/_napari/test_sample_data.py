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


@pytest.mark.slow
def test_the_series_samples_first_frame_reads_its_dry_mass_with_the_docks_defaults():
    """The time-series sample shows the tool where it is right: its cell (about 2 rad through it)
    reconstructed with the dock's defaults ('tv', z ±80 µm) and measured as Objects over time does:
    one object, its dry mass within 5 % of the truth, its centre within 2 µm of the truth's (the
    simulator's default swimmer, 5.4 rad, read 1.26 x its mass and 16 µm off in z)."""
    from napari_ssdpc.analysis.objects import REFRACTION_INCREMENT_UM3_PG, measure_objects
    from napari_ssdpc.calibration import calibrate
    from napari_ssdpc.reconstruction.reconstructor import Reconstructor
    from napari_ssdpc.settings.config import RunConfig
    from napari_ssdpc.simulation.moving import moving_sample

    flat, white = sample_data.series_flat_white()
    optics = sample_data.series_optics()
    res = Reconstructor(RunConfig.of(optics), calibrate(white, optics), flat=flat).reconstruct(
        np.asarray(sample_data.moving_sample_series(prefetch=False)[-1][0][0])
    )
    cell = moving_sample(sample_data.SERIES_FRAMES, **sample_data.SERIES_CELL)[0]
    body = 4 / 3 * np.pi * np.prod(cell.semi_axes_um)
    inclusion = 4 / 3 * np.pi * np.prod(cell.nucleus_semi_axes_um)
    dn, dn_inclusion = cell.n - cell.medium_index, cell.n_nucleus - cell.medium_index
    true_pg = (dn * (body - inclusion) + dn_inclusion * inclusion) / REFRACTION_INCREMENT_UM3_PG
    [found] = measure_objects(res.delta_n, res.z_um, res.y_um, res.x_um, n_medium=optics.medium_index)
    assert true_pg == pytest.approx(63.1, abs=0.05)
    assert found["dry_mass_pg"] / true_pg == pytest.approx(1.0, abs=0.05)  # measured 1.018
    centre = np.array([found["x_um"], found["y_um"], found["z_um"]])
    assert np.linalg.norm(centre - np.array(cell.center_um)) < 2.0  # measured 1.6 µm, along z
