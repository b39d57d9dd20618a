"""A cell and a bar target against the simulator's truth (slow; docs/validation.md)."""

import pytest

from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cell(cache):
    case = val.simulate_case("cell", ph.cell(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(-40, 40), stacks=False)
    return vt.cell_metrics(res, case.phantom, (20.7, 3.9))


@pytest.mark.xfail(
    strict=True, reason="measured: correlation 0.862 with the blurred truth (Tikhonov 0.566; 0.902 at NA 0.25)"
)
def test_cell_correlates_with_the_truth_at_the_system_resolution(cell):
    assert cell["correlation_blurred"] >= 0.9  # the target


def test_cell_nucleus_ri_matches_the_blurred_truth(cell):
    assert abs(cell["ri_nucleus"] - cell["ri_nucleus_blurred_truth"]) < 0.01  # measured 0.006


def test_bar_target_resolved_at_its_depth(cache):
    case = val.simulate_case("bars", ph.bar_target(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(0, 80), method="rl", stacks=True)
    m = vt.bar_metrics(res, case.phantom)
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
    assert vt.bar_metrics(res, case.phantom)["contrast"][4.38] > 0.10
