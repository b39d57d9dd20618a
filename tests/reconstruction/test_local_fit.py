"""The bead fit's local fit stops where its single-precision misfit stops resolving steps: a line
search probing below that resolution is ended, the best point kept and called converged."""

from types import SimpleNamespace

import numpy as np

from napari_ssdpc.reconstruction import bead_local_fit
from napari_ssdpc.reconstruction.bead_local_fit import local_fit

MINIMUM = np.array([[0.3, -0.2, 1.1, 2.4, 0.05]])  # x, y, z, R (µm), Δn
START = MINIMUM + np.array([[0.4, -0.3, 1.5, -0.5, 0.01]])


class Float32Quadratic:
    """A misfit of the spheres' five numbers with the curvature of a bead's, rounded to float32 as the
    model's sum is, and a gradient a little off (as an adjoint in single precision): near the
    minimum the line search probes steps the misfit cannot resolve."""

    def __init__(self):
        self.model = SimpleNamespace(dx=0.3, xp=np)
        self.weight = np.ones(40_000)  # the data points: the fit's tolerance is relative to them
        self.curvature = np.array([400.0, 400.0, 60.0, 900.0, 4e6])
        self.evaluations = 0

    def misfit_and_gradient(self, spheres):
        self.evaluations += 1
        d = spheres - MINIMUM
        value = np.float32(5.0 + 0.5 * float(np.sum(self.curvature * d * d)))
        return float(value), self.curvature * d + 0.01 * np.array([1.0, -1.0, 1.0, 1.0, -1.0])


def fitted(monkeypatch, patience):
    monkeypatch.setattr(bead_local_fit, "PATIENCE", patience)
    region = Float32Quadratic()
    spheres, value, converged = local_fit(region, START, np.array([1.0]), 60, (-10.0, 10.0))
    return spheres, value, converged, region.evaluations


def test_a_fit_at_its_misfits_resolution_stops(monkeypatch):
    stopped = fitted(monkeypatch, bead_local_fit.PATIENCE)
    probing = fitted(monkeypatch, 10_000)  # no stop: L-BFGS-B's own tests only
    np.testing.assert_allclose(stopped[0], MINIMUM, atol=3e-4)  # x, y, z, R within 0.3 nm; Δn within 3e-4
    np.testing.assert_allclose(stopped[0], probing[0], atol=1e-6)  # the same point
    assert stopped[1] <= probing[1]
    assert stopped[2]
    assert stopped[3] < probing[3], (stopped[3], probing[3])  # evaluations saved
