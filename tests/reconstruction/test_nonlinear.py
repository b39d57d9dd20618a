"""The one nonlinear solver: it finds the constrained least-squares answer of a model it is given
through the NonlinearModel protocol, on any backend, and its TV term has the right gradient."""

import numpy as np
import pytest

from napari_ssdpc.backend import Backend, cpu
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.reconstruction.nonlinear import (
    Fit,
    NonlinearModel,
    Unknowns,
    projected_gradient,
    smoothed_tv,
)


class Blur:
    """A toy model of the views: each 'view' is a known linear map of the volume plus the background 1
    (views = 1 + A x), with an exact misfit gradient: enough to check the solver against lstsq."""

    def __init__(self, shape, k, bk: Backend, seed=0):
        rng = np.random.default_rng(seed)
        self.bk, self.shape = bk, tuple(shape)
        self.view_shape = (k, shape[1], shape[2])
        n, m = int(np.prod(shape)), k * shape[1] * shape[2]
        self.a_host = (rng.standard_normal((m, n)) / np.sqrt(n)).astype(np.float32)
        self.a = bk.asarray(self.a_host)

    def views(self, dn):
        return 1.0 + (self.a @ dn.reshape(-1)).reshape(self.view_shape)

    def misfit(self, dn, measured, weight=None):
        r = self.views(dn) - measured
        w = r if weight is None else r * weight
        return 0.5 * float(self.bk.xp.sum(r * w)), (self.a.T @ w.reshape(-1)).reshape(self.shape)


def _problem(bk, sign):
    model = Blur((3, 4, 4), 6, bk)
    rng = np.random.default_rng(1)
    truth = np.abs(rng.standard_normal(model.shape)).astype(np.float32) * (1 if sign > 0 else -1)
    truth[:, 0, :] = 0.0  # outside the field stop
    measured = 1.0 + (model.a_host @ truth.ravel()).reshape(model.view_shape)
    inside = np.ones((1, 4, 4), np.float32)
    inside[:, 0, :] = 0.0
    lo, hi = (0.0, 10.0) if sign > 0 else (-10.0, 0.0)
    fit = Fit(
        model,
        bk.asarray(measured),
        bk.asarray(np.ones(model.view_shape, np.float32)),
        Unknowns(1, bk.xp),
        lo,
        hi,
        bk.asarray(inside),
    )
    return fit, truth


@pytest.mark.parametrize("sign", [1, -1])
def test_the_solver_finds_the_constrained_answer_of_a_model(sign):
    bk = cpu()
    fit, truth = _problem(bk, sign)
    assert isinstance(fit.model, NonlinearModel)
    res = projected_gradient(fit, np.zeros_like(truth), iterations=3000, tolerance=1e-7)
    assert res.converged
    np.testing.assert_allclose(res.x, truth, atol=2e-3 * np.abs(truth).max())
    assert np.all(res.x[:, 0, :] == 0) and np.all(sign * res.x >= 0)  # the constraints hold exactly
    obj = np.asarray(res.history["objective"])
    assert obj[-1] < 1e-5 * obj[0] and np.all(np.diff(obj) <= 1e-6 * obj[0])  # accepted steps never rise


def test_the_discrepancy_stop_ends_the_fit_when_the_data_are_explained():
    fit, truth = _problem(cpu(), 1)
    f0 = fit.objective(np.zeros_like(truth))[0]
    res = projected_gradient(fit, np.zeros_like(truth), iterations=3000, tolerance=0.0, enough=0.01 * f0)
    assert res.converged and res.history["objective"][-1] <= 0.01 * f0
    assert res.iterations < 200  # it stopped there, not at the limit


def test_the_solver_runs_on_a_device_backend_with_the_same_numbers():
    from fake_device import fake_gpu

    fit_c, truth = _problem(cpu(), 1)
    bk = fake_gpu()
    fit_d, _ = _problem(bk, 1)
    rc = projected_gradient(fit_c, np.zeros_like(truth), iterations=40, tolerance=0.0)
    rd = projected_gradient(fit_d, bk.asarray(np.zeros_like(truth)), iterations=40, tolerance=0.0)
    np.testing.assert_allclose(bk.to_host(rd.x), rc.x, rtol=1e-5, atol=1e-6)
    assert rd.history["objective"] == pytest.approx(rc.history["objective"], rel=1e-5)


def test_unknowns_on_the_views_grid_are_the_adjoint_pair():
    rng = np.random.default_rng(2)
    u = Unknowns(2, np)
    x, g = rng.standard_normal((2, 3, 3)), rng.standard_normal((2, 6, 6))
    assert np.sum(u.up(x) * g) == pytest.approx(np.sum(x * u.down(g)))
    assert u.up(x).shape == (2, 6, 6) and np.all(u.up(x)[:, :2, :2] == x[:, :1, :1])


def test_smoothed_tv_gradient_matches_finite_differences():
    rng = np.random.default_rng(4)
    x = rng.standard_normal((3, 5, 4))
    voxel = (2.0, 0.5, 0.5)
    value, grad = smoothed_tv(x, voxel, 0.1, np)
    d = np.diff(x, axis=2, append=x[:, :, -1:]) / 0.5
    assert value > np.abs(d).sum()  # at least the x part of the TV
    for _ in range(3):
        e = rng.standard_normal(x.shape)
        h = 1e-6
        fd = (smoothed_tv(x + h * e, voxel, 0.1, np)[0] - smoothed_tv(x - h * e, voxel, 0.1, np)[0]) / (2 * h)
        assert np.sum(grad * e) == pytest.approx(fd, rel=1e-5)


def test_a_view_model_is_built_from_any_transfer_functions():
    """ViewModel takes the TransferFunctions protocol: the lenslets' set keeps it, and another
    front end's (here a wrapper that keeps three views) gives the matching rows of the model."""
    from napari_ssdpc.physics import transfer
    from napari_ssdpc.reconstruction.forward import TransferFunctions, ViewModel
    from napari_ssdpc.settings.optics import Optics

    optics = Optics.paper().replace(condenser_na=0.3)
    lenslets = [ln for ln in nominal_lenslets(optics) if ln.fraction > 0.99][:6]
    setup = transfer.LensletSetup(optics, lenslets, (32, 32), optics.object_pixel_um)
    assert isinstance(setup, TransferFunctions)

    class FirstViews:
        """Another front end's transfer functions: the first three views of the lenslets'."""

        def __init__(self, inner):
            self.inner, self.i0, self.m_out = inner, inner.i0[:3], inner.m_out

        def band(self, zs):
            return tuple(h[:, :3] for h in self.inner.band(zs))

        def embed(self, h):
            return self.inner.embed(h)

    z = [-4.0, 0.0, 4.0]
    whole = ViewModel(setup, (32, 32), optics.object_pixel_um, z, i0=setup.i0)
    part = ViewModel(FirstViews(setup), (32, 32), optics.object_pixel_um, z, i0=setup.i0[:3])
    # the weights are relative to the brightest view of each model
    scale = (part.w[0] / whole.w[0]).item()
    np.testing.assert_allclose(part.a, whole.a[:, :3] * scale, rtol=1e-5, atol=1e-7)
