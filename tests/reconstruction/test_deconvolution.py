"""Richardson-Lucy over several views: adjointness, localisation in z, bad input."""

import numpy as np
import pytest

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.deconvolution import MultiViewRL, kernels_to_otf, padded_shape


def _parallax_kernels(n_views=4, zs=(-6, -3, 0, 3, 6), size=21, sigma=1.2):
    """Gaussian blur that grows with |z|, shifted by z * direction_k (a toy light field)."""
    dirs = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], float)[:n_views] * 0.8
    yy, xx = np.mgrid[:size, :size] - size // 2
    k = np.empty((n_views, len(zs), size, size), np.float32)
    for i, d in enumerate(dirs):
        for j, z in enumerate(zs):
            s = sigma + 0.15 * abs(z)
            g = np.exp(-((xx - z * d[0]) ** 2 + (yy - z * d[1]) ** 2) / (2 * s * s))
            k[i, j] = g / g.sum()
    return k


@pytest.fixture(scope="module")
def op():
    k = _parallax_kernels()
    shape = (48, 48)
    return MultiViewRL(kernels_to_otf(k, padded_shape(shape, k.shape[-2:])), shape), k


def test_forward_and_adjoint_are_adjoint(op):
    rl, _ = op
    rng = np.random.default_rng(1)
    o = rng.random((rl.z,) + rl.fft_shape).astype(np.float32)
    r = rng.random((rl.k,) + rl.fft_shape).astype(np.float32)
    lhs = np.vdot(rl.forward(o), r)
    rhs = np.vdot(o, rl.adjoint(r))
    assert lhs == pytest.approx(rhs, rel=1e-4)


def test_forward_matches_direct_convolution(op):
    from scipy.signal import fftconvolve

    rl, k = op
    o = np.zeros((rl.z,) + rl.fft_shape, np.float32)
    o[3, 20, 25] = 1.0
    v = rl.forward(o)[:, :48, :48]
    direct = fftconvolve(o[3, :48, :48], k[0, 3], mode="same")
    assert np.max(np.abs(v[0] - direct)) < 1e-5


def test_points_are_found_at_their_depth(op):
    rl, _ = op
    truth = np.full((rl.z,) + rl.fft_shape, 0.2, np.float32)
    truth[:, 48:, :] = truth[:, :, 48:] = 0
    truth[1, 15, 30] += 30.0  # z index 1
    truth[4, 32, 14] += 30.0  # z index 4
    views = np.clip(rl.forward(truth)[:, :48, :48], 0, None)
    res = rl.run(views, 40)
    assert np.argmax(res.stack[:, 15, 30]) == 1 and np.argmax(res.stack[:, 32, 14]) == 4
    # the relative change per iteration is recorded and decreases
    assert len(res.relative_change) == 40 and res.relative_change[-1] < res.relative_change[0]


def test_bad_input(op):
    rl, _ = op
    with pytest.raises(SsdpcError, match="iterations must be >= 1"):
        rl.run(np.ones((rl.k, 48, 48)), 0)
    with pytest.raises(SsdpcError, match="non-negative"):
        rl.run(-np.ones((rl.k, 48, 48)), 2)
    with pytest.raises(SsdpcError, match="rebuild the operators"):
        rl.run(np.ones((rl.k, 40, 48)), 2)
