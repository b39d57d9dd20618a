"""The TV-regularised inversion on small synthetic problems with a known answer."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.fft as sfft

from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.lattice import lenslet_case
from napari_ssdpc.reconstruction.forward import ViewModel, padded_planes
from napari_ssdpc.reconstruction.proximal import prox_two_kinks
from napari_ssdpc.reconstruction.regularised import TvInversion
from napari_ssdpc.settings.optics import Optics


@pytest.fixture(scope="module")
def setup():
    optics = Optics.paper().replace(condenser_na=0.3)
    lenslets = [ln for ln in nominal_lenslets(optics) if lenslet_case(optics, ln) == "straddling"][:8]
    shape, pixel = (64, 64), 0.8456
    z = np.arange(-10.0, 10.1, 2.0)
    yy, xx = np.mgrid[:64, :64]
    mask = np.hypot(yy - 32, xx - 32) < 30
    r_z = 20.0
    zs, planes = padded_planes(z, r_z)
    tv = TvInversion(ViewModel.for_lenslets(optics, lenslets, shape, pixel, zs), planes, r_z, mask=mask)
    return tv, mask, z


def _forward(tv, phi):
    """Views' contrast (K, ny, nx) of a phase volume on the requested planes, noise free."""
    model = tv.model
    full = np.zeros((tv.nz,) + tv.shape, np.float32)
    full[tv.planes] = phi
    band = model.forward(model.take(sfft.rfft2(full, norm="ortho")))  # (P, K)
    return model.images(band) / model.w[:, None, None]


def test_noise_is_measured_beyond_the_band(setup):
    tv, mask, _ = setup
    rng = np.random.default_rng(0)
    sigma = 0.01
    noise = rng.normal(0, sigma, (tv.model.n_views,) + tv.shape).astype(np.float32) * mask
    estimate = tv.noise(noise / tv.model.w[:, None, None])
    assert estimate == pytest.approx(sigma, rel=0.1)


def test_a_positive_blob_is_recovered_at_its_depth_and_with_its_sign(setup):
    tv, mask, z = setup
    yy, xx = np.mgrid[:64, :64]
    phi = np.zeros((len(z),) + tv.shape, np.float32)
    blob = (np.hypot(yy - 30, xx - 36) < 4).astype(np.float32) * 0.2
    iz = int(np.argmin(abs(z - 4.0)))
    phi[iz - 1 : iz + 2] = blob
    c = _forward(tv, phi) + np.random.default_rng(1).normal(0, 1e-3, (tv.model.n_views,) + tv.shape).astype(np.float32)
    out, report = tv.phase(c * mask, sign="auto", phi_max=1.0, iterations=60)
    assert report.sign.startswith("auto: denser")
    assert out.min() >= 0 and out.max() <= 1.0 and np.all(out[:, ~mask] == 0)  # the constraints hold
    profile = out[:, 30, 36]
    assert abs(z[int(np.argmax(profile))] - 4.0) <= 2.0  # the peak within one plane of the truth
    assert report.objective[-1] < report.objective[0]
    # the z-integrated phase at the blob's centre: the truth is 3 planes x 0.2 rad
    assert profile.sum() == pytest.approx(0.6, rel=0.5)


def test_bad_sign_is_one_line(setup):
    from napari_ssdpc.errors import SsdpcError

    tv, _, _ = setup
    with pytest.raises(SsdpcError, match="use one of auto, denser, lighter, any"):
        tv.phase(np.zeros((tv.model.n_views,) + tv.shape, np.float32), sign="up")


@pytest.mark.parametrize("move_px, fraction", [(0.0, 0.25), (0.3, 0.5)])
def test_a_solve_started_where_the_previous_frame_ended_needs_few_iterations(setup, move_px, fraction):
    """A series frame warm-started from the previous frame's TvState: the sign carried over (no
    probes), far fewer iterations than a cold solve to the same tolerance, the same answer. A
    resting object needs only the fresh noise removed; one that moved a third of a pixel more."""
    tv, mask, z = setup
    yy, xx = np.mgrid[:64, :64]
    rng = np.random.default_rng(2)
    iz = int(np.argmin(abs(z - 2.0)))

    def frame(x0):
        phi = np.zeros((len(z),) + tv.shape, np.float32)
        phi[iz - 1 : iz + 2] = np.clip(5.5 - np.hypot(yy - 32, xx - x0), 0, 1) * -0.15  # a soft-edged disk
        noise = rng.normal(0, 1e-3, (tv.model.n_views,) + tv.shape).astype(np.float32)
        return (_forward(tv, phi) + noise) * mask

    kw = dict(phi_max=1.0, iterations=300, tol=2e-3)
    _, first = tv.phase(frame(30.0), sign="auto", **kw)
    assert first.state.sign == "lighter" and not first.warm
    second = frame(30.0 + move_px)
    cold, cold_report = tv.phase(second, sign="auto", **kw)
    warm, warm_report = tv.phase(second, warm=first.state, sign="auto", **kw)
    assert warm_report.warm and warm_report.sign == "lighter" and not warm_report.sign_objectives
    assert warm_report.converged and cold_report.converged
    assert warm_report.iterations <= fraction * cold_report.iterations
    assert np.corrcoef(warm.ravel(), cold.ravel())[0, 1] > 0.995
    assert warm.max() <= 0 and np.all(warm[:, ~mask] == 0)  # the constraints hold


@pytest.mark.parametrize("p", [0.0, 0.3, -0.2])
def test_the_prox_of_sparsity_and_temporal_prior_is_the_exact_minimiser(p):
    """prox_two_kinks against a brute-force minimisation on a 1e-4 grid, and its clip against the
    minimisation restricted to a box (the sign constraint): both to the grid's step."""
    v = np.linspace(-0.8, 0.8, 33, dtype=np.float32)
    prior = np.full_like(v, p)
    grid = np.arange(-1.5, 1.5, 1e-4)
    for mu, gamma in [(0.05, 0.0), (0.05, 0.1), (0.1, 0.03), (0.0, 0.2)]:
        z = prox_two_kinks(v, prior, mu, gamma)
        cost = mu * abs(grid) + gamma * abs(grid - p) + 0.5 * (grid - v[:, None]) ** 2
        assert np.allclose(z, grid[np.argmin(cost, axis=1)], atol=2e-4)
        inside = grid >= 0  # the sign 'denser'
        boxed = grid[inside][np.argmin(cost[:, inside], axis=1)]
        assert np.allclose(np.clip(z, 0, None), boxed, atol=2e-4)


def _series(tv, mask, z, centres_px, seed):
    """Noisy views of a soft-edged positive disk at x = each centre (px), two planes thick."""
    yy, xx = np.mgrid[:64, :64]
    rng = np.random.default_rng(seed)
    iz = int(np.argmin(abs(z - 2.0)))
    out = []
    for x0 in centres_px:
        phi = np.zeros((len(z),) + tv.shape, np.float32)
        phi[iz : iz + 2] = np.clip(5.5 - np.hypot(yy - 32, xx - x0), 0, 1) * 0.15
        noise = rng.normal(0, 3e-3, (tv.model.n_views,) + tv.shape).astype(np.float32)
        out.append((_forward(tv, phi) + noise) * mask)
    return out


def _solve_series(tv, frames, weight):
    """Frame 0 cold, then each frame warm-started from the previous one with the temporal prior."""
    kw = dict(sign="denser", phi_max=1.0, tol=2e-3)
    phi, report = tv.phase(frames[0], iterations=80, **kw)
    out = [phi]
    for c in frames[1:]:
        phi, report = tv.phase(c, warm=report.state, iterations=20, temporal_weight=weight, **kw)
        assert report.temporal_weight == weight
        out.append(phi)
    return np.stack(out)


def test_the_temporal_prior_lowers_the_frame_to_frame_noise_of_a_resting_object(setup):
    """Six frames of a resting disk with fresh noise: the std over the frames of each voxel of the
    disk (and of the whole field) with the prior against the per-frame solutions (measured: 0.09 x
    on the disk, 0.57 x over the field)."""
    tv, mask, z = setup
    frames = _series(tv, mask, z, [32.0] * 6, seed=3)
    per_frame = _solve_series(tv, frames, 0.0)[1:]
    prior = _solve_series(tv, frames, 2.0)[1:]
    yy, xx = np.mgrid[:64, :64]
    disk = np.zeros(per_frame.shape[1:], bool)
    iz = int(np.argmin(abs(z - 2.0)))
    disk[iz : iz + 2] = np.hypot(yy - 32, xx - 32) < 6
    flicker = [float(np.std(s, axis=0)[disk].mean()) for s in (per_frame, prior)]
    assert flicker[1] < 0.25 * flicker[0], flicker
    field = [float(np.std(s, axis=0)[:, mask].mean()) for s in (per_frame, prior)]
    assert field[1] < 0.75 * field[0], field
    # the object keeps its phase: the z-integrated phase at its centre within 10% of the per-frame one
    through = [float(s[-1, :, 32, 32].sum()) for s in (per_frame, prior)]
    assert through[1] == pytest.approx(through[0], rel=0.1)


def test_the_temporal_prior_does_not_hold_a_moving_object_back(setup):
    """A disk moving 1 px a frame: the x centroid follows the truth within a quarter pixel with
    the prior as without (measured: 0.01 px without, 0.05 px at weight 2; weight 32 lags by
    0.6-1 px)."""
    tv, mask, z = setup
    centres = 28.0 + np.arange(6.0)
    frames = _series(tv, mask, z, centres, seed=4)
    xx = np.arange(64.0)
    for weight in (0.0, 2.0):
        phi = _solve_series(tv, frames, weight)
        column = np.clip(phi, 0, None).sum(axis=(1, 2))  # (T, nx)
        cx = (column * xx).sum(axis=1) / column.sum(axis=1)
        assert np.all(abs(cx - centres) < 0.25), (weight, cx - centres)


def test_the_temporal_weight_is_a_runtime_setting_with_a_flag():
    import argparse

    from napari_ssdpc.cli.options import add_reconstruction_options, config_from_args
    from napari_ssdpc.errors import SsdpcError
    from napari_ssdpc.settings import ReconstructionSettings

    parser = argparse.ArgumentParser()
    add_reconstruction_options(parser)
    rec = config_from_args(parser.parse_args(["--temporal-weight", "1.5"]), None).reconstruction
    assert rec.tv.temporal_weight == 1.5 and ReconstructionSettings().tv.temporal_weight == 0.0  # off by default
    assert rec.operator_key() == ReconstructionSettings().operator_key()  # the operators are kept
    with pytest.raises(SsdpcError, match="temporal_weight"):
        ReconstructionSettings.from_dict({"tv": {"temporal_weight": -1.0}})
