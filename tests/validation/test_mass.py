"""The strong-object measures (integrated Δn and tail along z) and the side-by-side figure, on
volumes whose answer is known."""

from types import SimpleNamespace

import numpy as np
import pytest

from napari_ssdpc.simulation.phantoms import Sphere
from napari_ssdpc.validation.figures import comparison_figure
from napari_ssdpc.validation.mass import mass_and_tail, masses_and_false
from napari_ssdpc.validation.truth import truth_volume

MEDIUM = 1.518


def _result(dn, z, y, x):
    return SimpleNamespace(
        delta_n=dn.astype(np.float32), ri=(MEDIUM + dn).astype(np.float32), z_um=z, y_um=y, x_um=x,
        voxel_um=(z[1] - z[0], y[1] - y[0], x[1] - x[0]),
    )  # fmt: skip


@pytest.fixture
def bead():
    z, y, x = np.arange(-30.0, 31.0), np.arange(-20.0, 20.5, 0.5), np.arange(-20.0, 20.5, 0.5)
    sphere = Sphere((2.0, -1.0, 4.0), 8.0, 1.49, medium_index=MEDIUM)
    empty = _result(np.zeros((z.size, y.size, x.size)), z, y, x)
    return sphere, truth_volume(sphere, empty, MEDIUM), (z, y, x)


def test_the_truth_keeps_all_its_mass_and_no_tail(bead):
    sphere, truth, grid = bead
    m = mass_and_tail(_result(truth, *grid), sphere, MEDIUM)
    assert m["integrated"] == pytest.approx(1.0, abs=1e-6) and m["tail"] == 0.0


def test_half_the_mass_and_a_column_along_z(bead):
    sphere, truth, grid = bead
    z, y, x = grid
    dn = 0.5 * truth
    column = np.zeros_like(truth)
    iy, ix = np.argmin(np.abs(y + 1.0)), np.argmin(np.abs(x - 2.0))
    far = np.abs(z - 4.0) > 4.0 + 8.0  # beyond the bead's surface by more than 8 µm
    column[far, iy, ix] = -0.001
    m = mass_and_tail(_result(dn + column, *grid), sphere, MEDIUM)
    expected_tail = 0.001 * far.sum() / np.abs(dn).sum()
    assert m["integrated"] == pytest.approx(0.5 + column.sum() / truth.sum(), rel=1e-5)
    assert m["tail"] == pytest.approx(expected_tail, rel=1e-5)
    # mass outside the disk (the bead's radius + 4 µm) does not count
    outside = np.zeros_like(truth)
    outside[30, 0, 0] = 1.0
    assert mass_and_tail(_result(truth + outside, *grid), sphere, MEDIUM)["integrated"] == pytest.approx(1.0, 1e-6)


def test_comparison_figure_draws_each_method(bead, tmp_path):
    sphere, truth, grid = bead
    path = comparison_figure(
        {"tv": _result(0.6 * truth, *grid), "multislice": _result(truth, *grid)}, sphere, MEDIUM, tmp_path / "c.png"
    )
    from PIL import Image

    w, h = Image.open(path).size
    assert w > 900 and h > 500  # two rows of three panels


def test_two_spheres_on_one_axis_each_keep_their_mass_and_a_floor_is_false(bead):
    _, _, (z, y, x) = bead
    lower, upper = Sphere((0.0, 0.0, -12.0), 5.0, 1.6), Sphere((0.0, 0.0, 12.0), 5.0, 1.6)
    empty = _result(np.zeros((z.size, y.size, x.size)), z, y, x)
    both = truth_volume(lower, empty, MEDIUM) + truth_volume(upper, empty, MEDIUM)
    m = masses_and_false(_result(both, z, y, x), [lower, upper], MEDIUM)
    assert m["masses"] == pytest.approx([1.0, 1.0]) and m["false"] == 0.0
    assert m["centroids_z_um"] == pytest.approx([0.0, 0.0], abs=0.05)
    only_upper = truth_volume(upper, empty, MEDIUM)
    floor = np.full(both.shape, 1e-4)  # a floor of Δn over the whole volume
    m = masses_and_false(_result(only_upper + floor, z, y, x), [lower, upper], MEDIUM)
    assert m["masses"][0] < 0.1 and m["masses"][1] > 1.0  # the lower one gone; the floor adds to both
    away = floor.sum() - floor[0, 0, 0] * 2 * np.count_nonzero(
        (np.hypot(*np.meshgrid(y, x, indexing="ij")) <= 6.5)[None] & (np.abs(z - 12)[:, None, None] <= 10.5)
    )
    assert m["false"] == pytest.approx(away / (2 * only_upper.sum()), rel=1e-6)
