"""DPC images (Eq. 1), Tikhonov phase (Eq. 7), RI conversion."""

import numpy as np
import pytest

from napari_ssdpc.reconstruction.dpc import dpc_image, phase_to_delta_n, tikhonov_phase


def test_dpc_image_range_and_sign():
    assert dpc_image(3.0, 1.0) == pytest.approx(0.5)
    assert dpc_image(1.0, 3.0, background=8.0) == pytest.approx(-0.25)


def test_tikhonov_recovers_phase_through_two_axis_transfer_functions():
    n = 64
    fy, fx = np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij")
    # two odd, imaginary toy transfer functions (one per axis), like DPC phase TFs
    hx = 1j * np.sin(2 * np.pi * fx) * np.exp(-(fx**2 + fy**2) / 0.05)
    hy = 1j * np.sin(2 * np.pi * fy) * np.exp(-(fx**2 + fy**2) / 0.05)
    yy, xx = np.mgrid[:n, :n] - n / 2
    phi = np.exp(-(xx**2 + yy**2) / 40.0)
    dpcs = [np.fft.ifft2(h * np.fft.fft2(phi)).real for h in (hx, hy)]
    rec = tikhonov_phase(dpcs, [hx, hy], alpha=1e-6)
    # the DC term is not transferred (H(0) = 0): compare without the mean
    err = np.linalg.norm((rec - rec.mean()) - (phi - phi.mean())) / np.linalg.norm(phi - phi.mean())
    assert err < 0.05


def test_phase_to_ri_units():
    # a 1 µm slice with Δn = 0.01 at 0.52 µm carries 2π·0.01/0.52 rad
    phi = 2 * np.pi * 0.01 / 0.52
    assert phase_to_delta_n(phi, 0.52, 1.0) == pytest.approx(0.01, rel=1e-6)
    assert phase_to_delta_n(-phi, 0.52, 1.0) == pytest.approx(-0.01, rel=1e-6)  # a lighter slab: Δn < 0
