"""The objects of a nonlinear fit's region and their checks; the region's edge held at the medium."""

import numpy as np
import pytest

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.fit_objects import fit_objects
from napari_ssdpc.reconstruction.multislice_region import medium_edge, object_support, unexplained_columns


def _two_objects():
    x = np.zeros((21, 30, 40))
    x[8:12, 5:10, 5:10] = 0.02  # object 1 at planes 8-11
    x[12:15, 18:24, 28:34] = -0.01  # object 2 at planes 12-14
    return x


def test_fit_objects_give_each_object_its_centre_mass_and_residual():
    dn = _two_objects()
    z, y, x = np.arange(21.0), 0.5 * np.arange(30), 0.5 * np.arange(40)
    misfit = np.full((30, 40), 1e-4)
    misfit[18:24, 28:34] = 9e-4  # the second object's views are 9 x the noise variance off
    objects = fit_objects(dn, misfit, z, y, x, noise=0.01, alpha_um3_pg=0.2, stop=3.0)
    first, second = sorted(objects, key=lambda o: o["centre_um"][0])
    assert first["centre_um"] == pytest.approx([3.5, 3.5, 9.5])
    assert second["centre_um"] == pytest.approx([15.25, 10.25, 13.0])
    assert first["dry_mass_pg"] == pytest.approx(0.02 * 100 * 0.25 / 0.2)  # Σ Δn dV / α
    assert second["dry_mass_pg"] == pytest.approx(-0.01 * 108 * 0.25 / 0.2)
    assert first["residual_over_noise"] == pytest.approx(1.0) and first["explained"]
    assert second["residual_over_noise"] == pytest.approx(9.0) and not second["explained"]


def test_the_medium_edge_frees_the_inside_only_and_refuses_a_region_it_would_fill():
    band = medium_edge(20, 0.5, 2.0)  # 4 pixels on each side
    assert band.shape == (1, 20, 20) and band[0, 4:16, 4:16].all() and band.sum() == 144
    with pytest.raises(SsdpcError, match="larger region"):
        medium_edge(10, 0.5, 2.5)


def test_two_objects_on_one_axis_are_two_objects_of_the_report():
    dn = np.zeros((30, 20, 20))
    dn[3:7, 8:12, 8:12] = 0.05  # below
    dn[20:24, 8:12, 8:12] = 0.03  # above, on the same axis
    dn[12, 0, 0] = 0.002  # a lone voxel: not an object, its Δn given to the nearest
    z, y, x = np.arange(30.0), np.arange(20.0), np.arange(20.0)
    objects = fit_objects(dn, np.zeros((20, 20)), z, y, x, noise=0.01, alpha_um3_pg=1.0, stop=3.0)
    assert [o["centre_um"] for o in objects] == [
        pytest.approx([9.5, 9.5, 4.5], abs=0.01),
        pytest.approx([9.5, 9.5, 21.5], abs=0.01),
    ]
    assert sum(o["dry_mass_pg"] for o in objects) == pytest.approx(dn.sum())  # every voxel given to one


def test_the_objects_support_keeps_every_object_grown_by_its_margin_and_nothing_far_away():
    dn = np.zeros((40, 20, 20))
    dn[5:9, 8:12, 8:12] = 0.05  # below
    dn[28:32, 8:12, 8:12] = 0.04  # above, on the same axis
    dn[18, 9, 9] = 0.004  # haze between them, below the objects' level
    support = object_support(dn, (1.0, 0.5, 0.5), 3.0)
    assert support[5:9, 8:12, 8:12].all() and support[28:32, 8:12, 8:12].all()  # both objects
    assert support[2, 10, 10] and support[11, 10, 10] and not support[12, 10, 10]  # 3 planes beyond, not 4
    assert support[6, 8, 5] and not support[6, 8, 1]  # 1.5 µm aside, not 3.5
    assert not support[18].any()  # the haze between them goes back to the medium
    assert object_support(np.zeros((4, 5, 5)), (1.0, 0.5, 0.5), 3.0).all()  # no object: nothing held


def test_the_columns_left_unexplained_are_those_the_data_still_ask_for():
    misfit = np.full((30, 30), 2e-4)  # 2 x the noise variance: explained under a stop of 3
    misfit[20:24, 5:9] = 1e-2  # an object held out of the support: its views are 100 x off
    misfit[2, 2] = 2e-3  # one noisy pixel (20 x the noise variance) alone is not an object
    cols = unexplained_columns(misfit, 0.01, 3.0, 0.5, 1.0)  # margin: 2 pixels
    assert cols[20:24, 5:9].all() and cols[18, 7] and not cols[15, 7]
    assert not cols[:10, :10].any()
    assert not unexplained_columns(misfit, 0.0, 3.0, 0.5, 1.0).any()  # noise unknown: nothing said
