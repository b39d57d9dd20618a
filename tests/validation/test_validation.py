"""Accuracy against the simulator's ground truth (slow: full-size simulations at condenser NA 0.3).

Targets from the pipeline issue; the measured numbers are in docs/validation.md. A target the
physics does not reach is an xfail with the measured number, strict so that it is noticed when
it starts to pass.
"""

import numpy as np
import pytest

from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("validation")


@pytest.fixture(scope="module")
def bead(cache):
    case = val.simulate_case("bead", ph.pmma_bead(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, stacks=False)
    return val.bead_metrics(res, case.phantom, 1.518)


@pytest.fixture(scope="module")
def two_beads(cache):
    case = val.simulate_case("two-beads", ph.two_beads(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, stacks=False)
    return [val.bead_metrics(res, s, 1.518) for s in case.phantom.spheres], case.phantom.spheres


def test_pmma_bead_is_negative_and_in_place(bead):
    assert bead["dn_centre"] < 0 and bead["dn_peak"] < 0
    cx, cy, cz = bead["centroid_um"]
    assert np.hypot(cx, cy) < 1.0  # lateral centroid within 1 µm
    assert abs(cz) < 5.0  # axial centroid within 5 µm


@pytest.mark.xfail(strict=True, reason="measured lateral FWHM 10.2 µm, 21.5% below 13 µm (target 20%)")
def test_pmma_bead_lateral_fwhm_within_20_percent(bead):
    assert bead["fwhm_x_um"] == pytest.approx(13.0, rel=0.2)
    assert bead["fwhm_y_um"] == pytest.approx(13.0, rel=0.2)


def test_pmma_bead_axial_fwhm_is_near_the_papers(bead):
    # the paper measured 21.96 µm; the design calculator predicts 20.7 µm
    assert 15.0 < bead["fwhm_z_um"] < 30.0


def test_two_beads_found_at_their_depths(two_beads):
    metrics, spheres = two_beads
    for m, s in zip(metrics, spheres):
        cx, cy, cz = m["centroid_um"]
        x, y, z = s.center_um
        assert m["dn_peak"] > 0
        assert abs(cz - z) < 5.0 and np.sign(cz) == np.sign(z)
        assert np.hypot(cx - x, cy - y) < 1.0
    assert metrics[0]["centroid_um"][2] < 0 < metrics[1]["centroid_um"][2]


def test_cell_correlates_with_the_truth_at_the_system_resolution(cache):
    case = val.simulate_case("cell", ph.cell(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(-40, 40), stacks=False)
    m = val.cell_metrics(res, case.phantom, (20.7, 3.9))
    assert m["correlation_blurred"] > 0.5  # measured 0.565
    assert abs(m["ri_nucleus"] - m["ri_nucleus_blurred_truth"]) < 0.02  # measured 0.0095


def test_bar_target_resolved_at_its_depth(cache):
    case = val.simulate_case("bars", ph.bar_target(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(0, 80), method="rl", stacks=True)
    m = val.bar_metrics(res, case.phantom)
    assert abs(m["best_focus_z_um"] - case.phantom.z_um) < 5.0  # measured 38 µm
    for period in (8.76, 6.2, 4.92):
        assert m["contrast"][period] > 0.10  # measured 1.0, 1.0, 0.13


@pytest.mark.xfail(
    strict=True,
    reason="measured contrast -0.01 at 15 RL iterations (0.09 at 40): 4.38 µm is "
    "at the sub-aperture cutoff (R_xy 3.9 µm)",
)
def test_bar_target_finest_element_resolved(cache):
    case = val.simulate_case("bars", ph.bar_target(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(0, 80), method="rl", stacks=True)
    assert val.bar_metrics(res, case.phantom)["contrast"][4.38] > 0.10
