"""The rest of a frame: the region's modelled views taken out of the frame's views."""

import numpy as np

from napari_ssdpc.reconstruction.rest_of_frame import rest_views


def test_the_region_s_model_is_taken_out_and_the_rest_is_kept():
    rng = np.random.default_rng(0)
    mask = np.ones((3, 20, 24), np.float32)
    mask[1, :, :4] = 0  # a view without data on its left
    strong = np.zeros((3, 20, 24), np.float32)
    strong[:, 5:15, 6:18] = rng.normal(0, 0.3, (3, 10, 12))  # a strong object's contrast, in the region
    weak = np.zeros((3, 20, 24), np.float32)
    weak[:, 2:8, 1:5] = 0.01  # a weak object, partly outside the region
    views = (1 + strong + weak) * mask
    region = (slice(4, 16), slice(5, 19))
    predicted = 1 + strong[:, region[0], region[1]]  # the model explains the strong object exactly
    before = views.copy()
    rest = rest_views(views, mask, predicted, region)
    np.testing.assert_allclose(rest, (1 + weak) * mask, atol=1e-6)
    assert rest.dtype == np.float32
    np.testing.assert_array_equal(views, before)  # the frame's views are not changed
