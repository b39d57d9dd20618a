"""The multislice refinement's start: the objects of the first-order solution."""

import numpy as np

from napari_ssdpc.reconstruction.methods.multislice import object_labels


def _two_objects():
    x = np.zeros((21, 30, 40))
    x[8:12, 5:10, 5:10] = 0.02  # object 1 at planes 8-11
    x[12:15, 18:24, 28:34] = -0.01  # object 2 at planes 12-14
    return x


def test_object_labels_find_each_object_and_give_every_pixel_the_nearest():
    labels, nearest = object_labels(_two_objects())
    assert labels.max() == 2 and np.count_nonzero(labels) == 25 + 36
    assert nearest[0, 0] == labels[7, 7] and nearest[-1, -1] == labels[20, 30] != nearest[0, 0]
