"""The multislice refinement's start: the objects of the first-order solution, and the search of
each object's depth before the fit."""

import numpy as np

from napari_ssdpc.reconstruction.methods.multislice import best_depths, object_labels


def _two_objects():
    x = np.zeros((21, 30, 40))
    x[8:12, 5:10, 5:10] = 0.02  # object 1 at planes 8-11
    x[12:15, 18:24, 28:34] = -0.01  # object 2 at planes 12-14
    return x


def test_object_labels_find_each_object_and_give_every_pixel_the_nearest():
    labels, nearest = object_labels(_two_objects())
    assert labels.max() == 2 and np.count_nonzero(labels) == 25 + 36
    assert nearest[0, 0] == labels[7, 7] and nearest[-1, -1] == labels[20, 30] != nearest[0, 0]


def test_each_object_moves_to_the_depth_the_misfit_prefers():
    truth = _two_objects()
    # the truth: object 1 three planes farther, object 2 two planes nearer than the start
    moved = np.zeros_like(truth)
    moved[11:15, 5:10, 5:10] = 0.02
    moved[10:13, 18:24, 28:34] = -0.01
    _, nearest = object_labels(truth)
    calls = []

    def misfit(a):
        calls.append(1)
        return float(np.sum((a - moved) ** 2))

    out, shifts = best_depths(truth, nearest, misfit, max_shift=4)
    assert shifts == [3, -2] and np.array_equal(out, moved)
    assert len(calls) == 2 * (1 + 8)  # per object: where it is, then 8 shifts


def test_an_object_already_at_its_best_depth_stays():
    x = _two_objects()
    _, nearest = object_labels(x)
    out, shifts = best_depths(x, nearest, lambda a: float(np.sum((a - x) ** 2)), max_shift=3)
    assert shifts == [0, 0] and np.array_equal(out, x)
