"""Wave-optics PSF (paper Eq. 6) against its fast per-lenslet form; parallax; normalisation."""

import numpy as np
import pytest
from scipy.special import j0, j1

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import nominal_lenslets, tan_theta
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.physics.psf import LensletPSF
from napari_ssdpc.physics.psf_reference import reference_psf
from napari_ssdpc.reconstruction.deconvolution import kernels_to_otf
from napari_ssdpc.settings.optics import Optics

Z = (-80.0, -30.0, 0.0, 30.0, 80.0)


@pytest.fixture(scope="module")
def optics():
    return Optics.paper()


@pytest.fixture(scope="module")
def ref(optics):
    return reference_psf(optics, None, Z)


@pytest.fixture(scope="module")
def fast(optics, ref):
    psf = LensletPSF(optics, ref.lenslets)
    windows, offsets = ref.windows(psf.shape)
    psf.offsets_px = offsets  # sample the kernels on the reference's pixels
    return psf, windows


def _centroid(img, offset=(0.0, 0.0)):
    h, w = img.shape
    yy, xx = np.mgrid[:h, :w]
    s = img.sum()
    return np.array([(img * (xx - w // 2)).sum() / s, (img * (yy - h // 2)).sum() / s]) + offset


def _tilt_direct(optics, lenslet, step=5e-4):
    """<u/η> over the sub-aperture ∩ pupil, hard edges, by a plain fine-grid sum."""
    rho = optics.subaperture_radius
    g = np.arange(-rho, rho + step, step)
    ux, uy = lenslet.u[0] + g[None, :], lenslet.u[1] + g[:, None]
    m = (np.hypot(g[None, :], g[:, None]) <= rho) & (np.hypot(ux, uy) <= optics.na / optics.wavelength_um)
    eta = np.sqrt((optics.medium_index / optics.wavelength_um) ** 2 - ux**2 - uy**2)
    return np.array([(m * ux / eta).sum(), (m * uy / eta).sum()]) / m.sum()


def test_fast_form_matches_eq6_reference(ref, fast):
    """Per-lenslet kernels reproduce the EI region of every lenslet of the full Eq. 6 PSF within
    1% relative L2 (the remainder is the neighbours' diffraction tail, absent from the fast form)."""
    psf, windows = fast
    assert len(psf.lenslets) == 32
    for i, z in enumerate(Z):
        k = psf.kernels(z)
        r = windows[i]
        err = np.linalg.norm((k - r).reshape(len(k), -1), axis=1) / np.linalg.norm(r.reshape(len(r), -1), axis=1)
        assert err.max() < 0.01, (z, err.max())


@pytest.mark.slow
def test_reference_is_converged_in_sampling(optics, ref, fast):
    """3x3 samples per pixel change the reference by < 0.2%; the fast form stays within 1%."""
    psf, _ = fast
    fine = reference_psf(optics, None, (-80.0, 80.0), oversample=3)
    windows, _ = fine.windows(psf.shape)
    for j, i in ((0, 0), (1, 4)):
        assert np.linalg.norm(fine.images[j] - ref.images[i]) / np.linalg.norm(fine.images[j]) < 2e-3
        k = psf.kernels(Z[i])
        err = np.linalg.norm((k - windows[j]).reshape(len(k), -1), axis=1)
        assert np.max(err / np.linalg.norm(windows[j].reshape(len(k), -1), axis=1)) < 0.01


def test_isolated_lenslet_matches_to_sampling_accuracy(optics):
    """Without neighbours (no spill-over) the two forms agree to 0.2%, clipped lenslet included."""
    sel = [ln for ln in nominal_lenslets(optics) if (ln.row, ln.col) in ((-1, -1), (1, 2))]
    ref = reference_psf(optics, sel, (-80.0, 80.0))
    psf = LensletPSF(optics, sel)
    windows, psf.offsets_px = ref.windows(psf.shape)
    for i, z in enumerate((-80.0, 80.0)):
        k = psf.kernels(z)
        ref_i = windows[i].reshape(2, -1)
        err = np.linalg.norm(k.reshape(2, -1) - ref_i, axis=1) / np.linalg.norm(ref_i, axis=1)
        assert err.max() < 2e-3, err


def test_parallax_is_the_pupil_weighted_mean_tilt(optics, ref, fast):
    """A point at depth z sits at z·<tanθ û>_k in EI k (|pupil|²-weighted), toward the axis for z > 0."""
    psf, windows = fast
    tilts = np.array([_tilt_direct(optics, ln) for ln in psf.lenslets])
    assert np.abs(psf.tilt - tilts).max() < 1e-4
    assert np.all(np.sum(tilts * np.array([ln.a_um for ln in psf.lenslets]), axis=1) < 0)  # toward the axis
    h, w = psf.shape
    yy, xx = np.mgrid[:h, :w]
    for i, z in enumerate(Z):
        expect = z * tilts / psf.pixel_um
        kern = psf.kernels(z)
        for k in range(len(kern)):
            # fast kernel: centroid of the whole window
            assert np.abs(_centroid(kern[k], psf.offsets_px[k]) - expect[k]).max() < 0.25
            # reference: centroid within 40 px of its brightest pixel (the neighbours' tails stay out)
            img = windows[i, k]
            py, px = np.unravel_index(np.argmax(img), img.shape)
            spot = img * (np.hypot(xx - px, yy - py) < 40)
            assert np.abs(_centroid(spot, psf.offsets_px[k]) - expect[k]).max() < 0.25


def test_central_and_edge_parallax_differ_from_the_centre_angle(optics, fast):
    """The effective tanθ of a half-clipped edge lenslet is ~6% below tanθ at its centre."""
    psf, _ = fast
    k = [i for i, ln in enumerate(psf.lenslets) if (ln.row, ln.col) == (1, 2)][0]
    u = np.array(psf.lenslets[k].u)
    ratio = np.dot(psf.tilt[k], u / np.linalg.norm(u)) / tan_theta(optics, u)[0]
    assert 0.92 < ratio < 0.95


def test_energy_normalisation(optics, ref, fast):
    psf, windows = fast
    # Eq. 6 conserves energy: the region holds the light of all lenslets (less the far tails)
    total = ref.images.sum(axis=(1, 2)) / sum(ln.fraction for ln in ref.lenslets)
    assert np.all((total > 0.99) & (total < 1.0))
    # on the whole EI window the fast kernels lack only the neighbours' spill-over (< 1%)
    full = LensletPSF(optics, psf.lenslets, support_px=145, offsets_px=psf.offsets_px)
    for i, z in enumerate(Z):
        ratio = full.kernels(z).sum(axis=(1, 2)) / windows[i].sum(axis=(1, 2))
        assert np.all((ratio > 0.99) & (ratio < 1.0)), z
    # an unclipped in-focus kernel on a square holds the Airy encircled energy of the inscribed
    # circle at least, and that of the circumscribed circle at most (sum over the plane = fraction)
    v = lambda r: 2 * np.pi * optics.subaperture_na * r / optics.wavelength_um
    ee = lambda r: 1 - j0(v(r)) ** 2 - j1(v(r)) ** 2
    for support in (None, 145):
        p = LensletPSF(optics, support_px=support)
        full = np.array([ln.fraction for ln in p.lenslets]) > 0.999
        s = p.kernels(0.0).sum(axis=(1, 2))[full]
        half = p.support_px // 2 * p.pixel_um
        assert np.all((s > ee(half)) & (s < ee(half * np.sqrt(2)))), (p.support_px, s.min(), s.max())


def test_grid_path_places_eis_behind_the_lenslets(optics):
    """With a calibrated-style Grid (axis off the vertex), in-focus spots sit at grid.lattice_px."""
    grid = Grid.nominal(optics, axis_offset_px=(3.3, -1.6))
    ref = reference_psf(optics, grid, 0.0)
    windows, offsets = ref.windows((61, 61))
    for k, ln in enumerate(ref.lenslets):
        if ln.fraction < 0.5:
            continue
        spot = ref.centres_px[k] + _centroid(windows[0, k], offsets[k])  # sensor (x, y) px
        assert np.abs(spot - grid.lattice_px(ln.row, ln.col)).max() < 0.05


def test_otf_matches_the_deconvolution_convention(fast):
    psf, _ = fast
    fft_shape = (300, 300)
    for z in (-80.0, 30.0):
        a = psf.otf(z, fft_shape)
        b = kernels_to_otf(psf.kernels(z), fft_shape)
        assert np.linalg.norm(a - b) / np.linalg.norm(b) < 1e-4
    both = psf.otf([-80.0, 30.0], fft_shape)
    assert both.shape == (len(psf.lenslets), 2, 300, 151) and both.dtype == np.complex64
    assert np.array_equal(both[:, 1], psf.otf(30.0, fft_shape))


def test_bad_input(optics):
    with pytest.raises(SsdpcError, match="unrotated"):
        reference_psf(optics, Grid.nominal(optics, rotation_deg=2.0), 0.0)
    with pytest.raises(SsdpcError, match="odd integer"):
        reference_psf(optics, None, 0.0, oversample=2)
    psf = LensletPSF(optics)
    with pytest.raises(SsdpcError, match="larger one"):
        psf.otf(0.0, (64, 64))
    with pytest.raises(SsdpcError, match="no lenslets"):
        LensletPSF(optics, [])
    with pytest.raises(SsdpcError, match="offsets_px must have shape"):
        LensletPSF(optics, offsets_px=np.zeros((3, 2)))
