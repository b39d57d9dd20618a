"""Array backend: NumPy by default, CuPy on request; banded Richardson-Lucy operators.

GPU tests run only where CuPy sees a CUDA GPU; everything else is checked with NumPy."""

import threading
import types

import numpy as np
import pytest

from napari_ssdpc import backend, blas
from napari_ssdpc.backend import get_backend, gpu_available
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.reconstruction.deconvolution import Band, MultiViewRL
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics

needs_gpu = pytest.mark.skipif(not gpu_available(), reason="needs CuPy and a CUDA GPU")


def test_cpu_backend_is_numpy_and_scipy_fft():
    bk = get_backend("cpu")
    assert bk.xp is np and not bk.is_gpu and get_backend(bk) is bk and get_backend(None).device == "cpu"
    a = np.random.default_rng(0).random((3, 20, 18)).astype(np.float32)
    assert isinstance(bk.asarray(a), np.ndarray) and bk.to_host(a) is a
    np.testing.assert_allclose(bk.irfft2(bk.rfft2(a), s=a.shape[-2:]), a, atol=1e-6)
    # the split transforms (rfft along x, fft along y) make the same spectrum as rfft2
    np.testing.assert_allclose(bk.fft_(bk.rfft(a), axis=-2), bk.rfft2(a), atol=1e-4)


def test_unknown_device_is_a_one_line_error():
    with pytest.raises(SsdpcError, match="unknown device 'tpu'; use one of cpu, gpu"):
        get_backend("tpu")


def test_gpu_without_cupy_names_the_install(monkeypatch):
    def no_cupy(name):
        raise ImportError(name)

    monkeypatch.setattr(backend, "_import", no_cupy)
    with pytest.raises(SsdpcError, match=r"needs CuPy.*napari-ssdpc\[gpu\].*--device cpu") as e:
        get_backend("gpu")
    assert "\n" not in str(e.value)
    assert not gpu_available()
    # the Reconstructor asks for its backend first: no operators are built for nothing
    with pytest.raises(SsdpcError, match="needs CuPy"):
        Reconstructor(RunConfig.of(Optics.paper(), device="gpu"), None)


def test_gpu_with_cupy_but_no_device(monkeypatch):
    def runtime_error():
        raise RuntimeError("cudaErrorNoDevice")

    runtime = types.SimpleNamespace(getDeviceCount=runtime_error)
    fake = types.SimpleNamespace(cuda=types.SimpleNamespace(runtime=runtime))
    monkeypatch.setattr(backend, "_import", lambda name: fake)
    with pytest.raises(SsdpcError, match="found no CUDA GPU"):
        get_backend("gpu")


# ------------------------------------------------------------------ banded RL
def _band_limited_otfs(shape=(64, 60), k=3, z=4, radius=0.2, seed=0):
    """OTFs of random real kernels with everything outside the band set to zero."""
    rng = np.random.default_rng(seed)
    kernels = rng.random((k, z) + shape).astype(np.float32)
    otf = np.fft.rfft2(kernels).astype(np.complex64)
    band = Band.disk(shape, radius)
    keep = np.zeros(otf.shape[-2:], bool)
    band.put(keep, np.ones(band.box_shape, bool))
    return otf * keep, band


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_products_run_on_one_blas_thread_and_give_the_threads_back():
    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(0)
    a = rng.standard_normal((50, 16, 285)).astype(np.complex64)
    b = rng.standard_normal((50, 285, 1)).astype(np.complex64)
    with threadpool_limits(3, user_api="blas"):  # as on a 3-core machine
        if not _blas_threads():
            pytest.skip("no BLAS library that threadpoolctl can steer")
        with blas.one_blas_thread:
            assert set(_blas_threads()) == {1}
            with blas.one_blas_thread:  # nested: one shared hold
                assert set(_blas_threads()) == {1}
            assert set(_blas_threads()) == {1}
            inside = threading.Thread(target=lambda: np.testing.assert_array_equal(blas.matmul(a, b), a @ b))
            inside.start()
            inside.join()  # a concurrent holder leaving does not end this one
            assert set(_blas_threads()) == {1}
        assert set(_blas_threads()) == {3}  # the last holder out restores them
        np.testing.assert_allclose(blas.matmul(a, b), a @ b, rtol=1e-5)
        assert set(_blas_threads()) == {3}


def test_band_take_and_put_are_inverse():
    band = Band.disk((64, 60), 0.2)
    assert band.box_shape == (2 * 12 + 1, 13) and 0 < band.fraction < 0.25
    spec = np.arange(64 * 31).reshape(64, 31).astype(np.complex64)
    out = np.zeros_like(spec)
    band.put(out, band.take(spec))
    f = np.fft.fftfreq(64)
    rows = np.abs(f) <= 12 / 64
    assert np.array_equal(out[rows, :13], spec[rows, :13]) and not out[~rows].any() and not out[:, 13:].any()
    assert Band.disk((64, 60), 0.6).is_full


def test_banded_operators_equal_the_full_spectrum_ones():
    otf, band = _band_limited_otfs()
    view = (40, 36)
    rng = np.random.default_rng(1)
    mask = rng.random(view) > 0.1
    full = MultiViewRL(otf, view, mask)
    banded = MultiViewRL(band.take(otf), view, mask, band=band, backend="cpu")
    assert banded.fft_shape == full.fft_shape == (64, 60)
    o = rng.random((4, 64, 60)).astype(np.float32)
    r = rng.random((3, 64, 60)).astype(np.float32)
    np.testing.assert_allclose(banded.forward(o), full.forward(o), rtol=0, atol=1e-4 * np.abs(full.forward(o)).max())
    np.testing.assert_allclose(banded.adjoint(r), full.adjoint(r), rtol=0, atol=1e-4 * np.abs(full.adjoint(r)).max())
    # adjoint pair on the band, too
    assert np.vdot(banded.forward(o), r) == pytest.approx(np.vdot(o, banded.adjoint(r)), rel=1e-4)
    views = np.clip(full.forward(rng.random((4, 64, 60)).astype(np.float32))[:, :40, :36], 0, None)
    a, b = full.run(views, 5), banded.run(views, 5)
    assert np.max(np.abs(a.stack - b.stack)) <= 1e-4 * np.abs(a.stack).max()
    assert a.relative_change == pytest.approx(b.relative_change, rel=1e-3)


def test_odd_fft_width_keeps_its_shape():
    """A band carries the true FFT shape, so an odd width (next_fast_len may give one) is kept."""
    otf, band = _band_limited_otfs(shape=(48, 45), k=2, z=3)
    rl = MultiViewRL(band.take(otf), (30, 30), band=band)
    assert rl.fft_shape == (48, 45) and rl.forward(np.ones((3, 48, 45), np.float32)).shape == (2, 48, 45)


@needs_gpu
def test_gpu_operators_match_the_cpu():
    otf, band = _band_limited_otfs()
    rng = np.random.default_rng(2)
    views = rng.random((3, 40, 36)).astype(np.float32)
    cpu = MultiViewRL(band.take(otf), (40, 36), band=band, backend="cpu").run(views, 5)
    gpu = MultiViewRL(band.take(otf), (40, 36), band=band, backend="gpu").run(views, 5)
    assert isinstance(gpu.stack, np.ndarray)
    assert np.max(np.abs(gpu.stack - cpu.stack)) <= 1e-4 * np.abs(cpu.stack).max()


def test_operators_pickle_without_their_scratch_buffers():
    import pickle

    otf, band = _band_limited_otfs()
    rl = MultiViewRL(band.take(otf), (40, 36), band=band, workspace={})
    views = np.random.default_rng(3).random((3, 40, 36)).astype(np.float32)
    before = rl.run(views, 3).stack
    copy = pickle.loads(pickle.dumps(rl))
    assert copy.bk.device == "cpu" and pickle.loads(pickle.dumps(get_backend("cpu"))).xp is np
    np.testing.assert_array_equal(copy.run(views, 3).stack, before)


# ------------------------------------------------------------ the phase methods on a device
def test_the_fake_device_keeps_cupys_rules():
    """The stand-in the device tests use refuses what CuPy refuses: host and device arrays meet
    only through bk.asarray and bk.to_host."""
    from fake_device import fake_gpu

    bk = fake_gpu()
    d = bk.asarray(np.ones(3, np.float32))
    with pytest.raises(TypeError, match="use bk.xp.sum"):
        np.sum(d)
    with pytest.raises(TypeError, match="move it with bk.asarray"):
        d + np.ones(3, np.float32)
    with pytest.raises(TypeError, match="bk.to_host"):
        np.asarray(d)
    assert float(bk.xp.sum(d * 2)) == 6.0 and np.array_equal(bk.to_host(d), np.ones(3))


def _tv_on(device):
    from napari_ssdpc.physics.lattice import lenslet_case
    from napari_ssdpc.reconstruction.forward import ViewModel, padded_planes
    from napari_ssdpc.reconstruction.regularised import TvInversion
    from napari_ssdpc.reconstruction.wotf import WotfInversion

    optics = Optics.paper().replace(condenser_na=0.3)
    lenslets = [ln for ln in nominal_lenslets(optics) if lenslet_case(optics, ln) == "straddling"][:8]
    yy, xx = np.mgrid[:64, :64]
    mask = np.hypot(yy - 32, xx - 32) < 30
    zs, planes = padded_planes(np.arange(-10.0, 10.1, 2.0), 20.0)
    model = ViewModel.for_lenslets(optics, lenslets, (64, 64), 0.8456, zs, backend=device)
    rng = np.random.default_rng(0)
    c = (rng.normal(0, 1e-2, (model.n_views, 64, 64)) * mask).astype(np.float32)
    c[:, 28:36, 30:38] += 0.05  # something for the solve to find
    warm = WotfInversion(model.planes(planes), 1e-2).phase(c)
    return warm, TvInversion(model, planes, 20.0, mask=mask).phase(c, warm=warm, sign="auto", phi_max=1.0)


def test_tv_and_wotf_run_on_a_device_backend():
    from fake_device import fake_gpu

    (w_cpu, (tv_cpu, rep_cpu)), (w_dev, (tv_dev, rep_dev)) = _tv_on("cpu"), _tv_on(fake_gpu())
    assert isinstance(w_dev, np.ndarray) and isinstance(tv_dev, np.ndarray)
    assert np.abs(tv_cpu).max() > 0
    np.testing.assert_allclose(w_dev, w_cpu, rtol=0, atol=1e-6 * np.abs(w_cpu).max())
    np.testing.assert_allclose(tv_dev, tv_cpu, rtol=0, atol=1e-5 * np.abs(tv_cpu).max())
    assert rep_dev.iterations == rep_cpu.iterations and rep_dev.sign == rep_cpu.sign


@needs_gpu
def test_gpu_tv_matches_the_cpu():
    (w_cpu, (tv_cpu, _)), (w_gpu, (tv_gpu, rep)) = _tv_on("cpu"), _tv_on("gpu")
    assert isinstance(tv_gpu, np.ndarray) and rep.iterations > 0
    assert np.max(np.abs(w_gpu - w_cpu)) <= 1e-4 * np.abs(w_cpu).max()
    assert np.max(np.abs(tv_gpu - tv_cpu)) <= 1e-3 * np.abs(tv_cpu).max()


def _multislice_on(device):
    from napari_ssdpc.physics.views_multislice import ViewsMultislice

    optics = Optics.paper().replace(condenser_na=0.3)
    lenslets = [ln for ln in nominal_lenslets(optics) if ln.fraction > 0.99][:6]
    x = (np.arange(24) - 11.5) * optics.object_pixel_um
    model = ViewsMultislice(optics, lenslets, x, x, [-2.0, 0.0, 2.0], source_spacing_na=0.06, backend=device)
    rng = np.random.default_rng(7)
    dn = (0.02 * rng.standard_normal(model.shape)).astype(np.float32)
    data = (1 + 0.05 * rng.standard_normal(model.view_shape)).astype(np.float32)
    value, grad = model.misfit(model.bk.asarray(dn), model.bk.asarray(data))
    return model.bk.to_host(model.views(model.bk.asarray(dn))), value, model.bk.to_host(grad)


@needs_gpu
def test_gpu_multislice_model_matches_the_cpu():
    (v_cpu, f_cpu, g_cpu), (v_gpu, f_gpu, g_gpu) = _multislice_on("cpu"), _multislice_on("gpu")
    assert np.max(np.abs(v_gpu - v_cpu)) <= 1e-4 * np.abs(v_cpu).max()
    assert f_gpu == pytest.approx(f_cpu, rel=1e-4)
    assert np.max(np.abs(g_gpu - g_cpu)) <= 1e-3 * np.abs(g_cpu).max()
