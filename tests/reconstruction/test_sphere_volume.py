"""The voxelised spheres of the bead fit: their integral, and the gradient the fit follows."""

import math

import numpy as np
import pytest

from napari_ssdpc.reconstruction.sphere_volume import spheres_gradient, spheres_volume

X = np.arange(-12, 12.01, 0.4)
Z = np.arange(-8, 8.01, 0.5)


@pytest.mark.parametrize("radius", [1.0, 2.5, 4.3])
def test_integral_is_the_sphere_volume_times_dn(radius):
    sphere = [0.13, -0.27, 0.31, radius, 0.05]
    vol = spheres_volume([sphere], Z, X, X, 0.5)
    integral = float(vol.sum()) * 0.4 * 0.4 * 0.5
    truth = 4 / 3 * math.pi * radius**3 * 0.05
    assert integral == pytest.approx(truth, rel=0.02 if radius > 2 else 0.05)


def test_two_spheres_add_and_stay_where_they_are():
    a, b = [-5.0, 0.0, -3.0, 2.0, 0.1], [5.0, 1.0, 3.0, 1.5, -0.02]
    both = spheres_volume([a, b], Z, X, X, 0.5)
    assert np.allclose(both, spheres_volume([a], Z, X, X, 0.5) + spheres_volume([b], Z, X, X, 0.5))
    pos = np.clip(both, 0, None)
    zz, yy, xx = np.meshgrid(Z, X, X, indexing="ij")
    centre = [float(np.sum(g * pos) / pos.sum()) for g in (xx, yy, zz)]
    assert centre == pytest.approx([-5.0, 0.0, -3.0], abs=0.02)
    assert both.min() == pytest.approx(-0.02, abs=1e-6)


def test_gradient_matches_finite_differences():
    """The chain rule of the fit: d(Σ w Δn)/d(x, y, z, R, Δn) against central differences."""
    rng = np.random.default_rng(1)
    w = rng.normal(size=(len(Z), len(X), len(X)))
    w = np.cumsum(np.cumsum(w, axis=1), axis=2)  # smooth weights: the ramp's kinks average out
    sphere = np.array([0.21, -0.33, 0.17, 2.3, 0.07])
    grad = spheres_gradient([sphere], w, Z, X, X, 0.5)[0]
    steps = [0.02, 0.02, 0.02, 0.02, 1e-4]
    for i, h in enumerate(steps):
        e = np.zeros(5)
        e[i] = h
        hi = float(np.sum(w * spheres_volume([sphere + e], Z, X, X, 0.5)))
        lo = float(np.sum(w * spheres_volume([sphere - e], Z, X, X, 0.5)))
        assert grad[i] == pytest.approx((hi - lo) / (2 * h), rel=0.03, abs=1e-3 * abs(grad).max())
