"""The paper's PMMA bead with the default method against the simulator's truth (slow; docs/validation.md)."""

import numpy as np
import pytest

from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def bead(cache):
    case = val.simulate_case("bead", ph.pmma_bead(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, stacks=False)  # the default method, 'tv'
    assert res.settings["method"] == "tv" and res.settings["tv_sign"].startswith("auto: lighter")
    return vt.bead_metrics(res, case.phantom, 1.518)


def test_pmma_bead_is_negative_and_in_place(bead):
    assert bead["dn_centre"] < 0 and bead["dn_peak"] < 0
    cx, cy, cz = bead["centroid_um"]
    assert np.hypot(cx, cy) < 1.0  # lateral centroid within 1 µm
    assert abs(cz) < 2.0  # axial centroid within 2 µm (measured +1.7 µm; Tikhonov: +3.2 µm)


def test_pmma_bead_peak_is_at_least_half_the_truth(bead):
    assert bead["dn_peak"] < 0.5 * -0.028  # measured −0.021 (Tikhonov: −0.0075)


@pytest.mark.xfail(
    strict=True,
    reason="measured: Δn summed along z through the centre 1.36 x the true optical path (the missing cone's tails)",
)
def test_pmma_bead_optical_path_within_10_percent(bead):
    assert bead["opd_ratio"] == pytest.approx(1.0, rel=0.1)


def test_pmma_bead_lateral_fwhm_within_20_percent(bead):
    assert bead["fwhm_x_um"] == pytest.approx(13.0, rel=0.2)  # measured 10.8 µm (Tikhonov 10.2 µm)
    assert bead["fwhm_y_um"] == pytest.approx(13.0, rel=0.2)


def test_pmma_bead_axial_fwhm_is_between_the_bead_and_the_papers(bead):
    # the bead is 13 µm long; the paper measured 21.96 µm; measured 14.4 µm (Tikhonov 21 µm)
    assert 13.0 < bead["fwhm_z_um"] < 22.0
