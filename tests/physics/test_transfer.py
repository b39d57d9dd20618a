"""Weak-object transfer functions: normalisation, symmetry, the three lenslet cases, the σ → 1
collapse, an exact direct integral and an Abbe (source-point sum) simulation of the images."""

import numpy as np
import pytest
import scipy.fft as sfft

from napari_ssdpc.errors import SsdpcWarning
from napari_ssdpc.physics.dpc_transfer import dpc_from_halves, dpc_transfer_functions
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.lattice import lenslet_case
from napari_ssdpc.physics.pupil import axial_frequency
from napari_ssdpc.physics.transfer import (
    lenslet_transfer_functions,
    paper_transfer_functions,
    weak_object_transfer_functions,
)
from napari_ssdpc.settings.lenslets import circle_overlap_fraction
from napari_ssdpc.settings.optics import Optics


@pytest.fixture(scope="module")
def optics():
    return Optics.paper()


def _grid(n, du):
    f = sfft.fftfreq(n, 1.0 / (n * du))
    return f[None, :], f[:, None]


def _negate(h):
    """h(−u) on an unshifted FFT grid."""
    ny, nx = h.shape[-2:]
    return h[..., (-np.arange(ny)) % ny, :][..., (-np.arange(nx)) % nx]


def _lenslet(optics, row, col):
    return [ln for ln in nominal_lenslets(optics) if (ln.row, ln.col) == (row, col)][0]


def test_symmetric_full_disk(optics):
    ux, uy = _grid(128, 0.02)
    r = np.hypot(ux, uy)
    source = (r <= 0.15).astype(float)
    pupil = (r <= optics.cutoff).astype(complex)
    h_abs, h_phase = weak_object_transfer_functions(source, pupil)
    assert h_abs[0, 0].real == pytest.approx(2.0, abs=1e-9)
    assert np.abs(h_abs.imag).max() < 1e-9
    assert np.abs(h_phase).max() < 1e-9  # symmetric S and P: no phase contrast


def test_half_source_phase_tf_is_imaginary_and_odd(optics):
    tfs = paper_transfer_functions(optics.replace(condenser_na=0.3), (97, 97), optics.object_pixel_um)
    h = tfs["up"][1]
    peak = np.abs(h).max()
    assert peak > 0.3
    assert np.abs(h.real).max() < 1e-6 * peak
    assert np.abs(h + _negate(h)).max() < 1e-6 * peak
    # with defocus it stays Hermitian (a real phase gives a real image)
    hz = paper_transfer_functions(optics, (97, 97), optics.object_pixel_um, 20.0)["left"][1]
    assert np.abs(hz - np.conj(_negate(hz))).max() < 1e-6 * np.abs(hz).max()
    assert np.abs(hz.real).max() > 0.05 * np.abs(hz).max()  # defocus adds an even real part


def _direct_wotf(optics, ln, u, z, step=5e-4):
    """WOTF of one lenslet by a plain sum over the source disk, hard edges."""
    rho = optics.subaperture_radius
    g = np.arange(-rho, rho + step, step)
    wx, wy = ln.u[0] + g[None, :], ln.u[1] + g[:, None]

    def pupil(ax, ay):
        return (np.hypot(ax - ln.u[0], ay - ln.u[1]) <= rho) & (np.hypot(ax, ay) <= optics.cutoff)

    s = np.hypot(wx, wy) <= optics.source_radius
    eta = lambda ax, ay: axial_frequency(ax, ay, optics)
    f = s * pupil(wx + u[0], wy + u[1]) * pupil(wx, wy)
    f = f * np.exp(2j * np.pi * z * (eta(wx + u[0], wy + u[1]) - eta(wx, wy)))
    return f.sum() * step**2 / (np.pi * optics.source_radius**2)


@pytest.mark.parametrize("z", [0.0, 40.0])
def test_fft_wotf_matches_direct_integral(optics, z):
    ln = _lenslet(optics, -1, -1)  # straddles the source edge
    shape, pix = (145, 145), optics.object_pixel_um
    du = 1.0 / (shape[0] * pix)
    h_abs, h_phase, i0 = lenslet_transfer_functions(optics, [ln], shape, pix, z)
    d = np.hypot(*ln.u)
    exact_i0 = (
        circle_overlap_fraction(d, optics.subaperture_radius, optics.source_radius)
        * (optics.subaperture_radius / optics.source_radius) ** 2
    )
    assert i0[0] == pytest.approx(exact_i0, rel=2e-3)
    peak = np.abs(h_phase[0]).max()
    for m in [(3, 0), (0, 6), (5, -9), (-12, 4), (20, 7)]:
        u = (m[1] * du, m[0] * du)
        w_pos = _direct_wotf(optics, ln, u, z)
        w_neg = np.conj(_direct_wotf(optics, ln, (-u[0], -u[1]), z))
        assert abs(h_abs[0][m] - (w_pos + w_neg)) < 3e-3 * abs(w_pos + w_neg)
        assert abs(h_phase[0][m] - 1j * (w_pos - w_neg)) < 5e-3 * peak


def test_three_lenslet_cases(optics):
    o = optics.replace(condenser_na=0.25)  # source radius 0.48 cycles/µm
    inside, straddling, outside = _lenslet(o, -1, -1), _lenslet(o, -1, 1), _lenslet(o, -3, -1)
    assert [lenslet_case(o, ln) for ln in (inside, straddling, outside)] == ["inside", "straddling", "outside"]
    h_abs, h_phase, i0 = lenslet_transfer_functions(o, [inside, straddling, outside], (145, 145), o.object_pixel_um)
    # inside: the WOTF is the autocorrelation of the sub-aperture, even -> no in-focus phase contrast
    assert i0[0] == pytest.approx((o.subaperture_radius / o.source_radius) ** 2, rel=2e-3)
    assert np.abs(h_phase[0]).max() < 1e-6 * i0[0]
    # straddling: DPC-like, odd, imaginary, of the order of its background
    peak = np.abs(h_phase[1]).max()
    assert peak > 0.1 * i0[1]
    assert np.abs(h_phase[1] + _negate(h_phase[1])).max() < 1e-6 * peak
    assert np.abs(h_phase[1].real).max() < 1e-6 * peak
    # outside: dark field, no direct light, nothing at first order
    assert i0[2] == 0 and np.abs(h_abs[2]).max() == 0 and np.abs(h_phase[2]).max() == 0
    # a source that fills the sub-aperture makes the image incoherent: W(u) = W*(−u) at every z,
    # so an inside lenslet has no first-order phase contrast even out of focus (absorption only)
    ha, hz, _ = lenslet_transfer_functions(o, [inside, straddling], (145, 145), o.object_pixel_um, 30.0)
    assert np.abs(hz[0]).max() < 1e-6 * i0[0]
    assert np.abs(ha[0]).max() == pytest.approx(2 * i0[0], rel=1e-3)
    assert np.abs(hz[1].real).max() > 0.05 * i0[1]  # straddling: defocus adds an even part


def _with_condenser(optics, na_c):
    if na_c > 0.8 * optics.na:  # Optics itself warns above 0.8 NA
        with pytest.warns(SsdpcWarning, match="above 0.8"):
            return optics.replace(condenser_na=na_c)
    return optics.replace(condenser_na=na_c)


def test_dpc_phase_collapses_as_sigma_goes_to_one(optics):
    """Full source, split detection pupil: the in-focus DPC phase TF vanishes as σ → 1 (docs/conventions.md)."""
    contrast = {}
    for na_c in (0.1, 0.36, 0.38, 0.39, 0.399):
        d = dpc_transfer_functions(_with_condenser(optics, na_c), shape=(97, 97), warn=False)
        contrast[na_c] = d["contrast"]["ud"]
        assert d["contrast"]["lr"] == pytest.approx(d["contrast"]["ud"], rel=1e-5)
    assert contrast[0.1] > 0.4
    assert contrast[0.36] > contrast[0.38] > contrast[0.39] > contrast[0.399]
    assert contrast[0.399] < 0.01
    # the paper's half-source model does not show it: its contrast stays at the pupil edge
    o = _with_condenser(optics, 0.399)
    assert dpc_transfer_functions(o, shape=(97, 97), model="paper", warn=False)["contrast"]["ud"] > 0.5
    # and the user is told
    with pytest.warns(SsdpcWarning, match="too weak to invert"):
        dpc_transfer_functions(o, shape=(97, 97))


def test_dpc_tf_is_one_half_over_its_own_background(optics):
    d = dpc_transfer_functions(optics)
    assert d["I0"]["up"] == pytest.approx(d["I0"]["down"], rel=1e-9)
    np.testing.assert_allclose(d["dpc_phase"]["ud"], d["H_phase"]["up"] / d["I0"]["up"], atol=1e-6)
    # at the paper's NA_c = 0.1 only the 4 central lenslets are lit; each half collects 42.7%
    total = sum(d["I0"][h] for h in ("up", "down"))
    exact = (
        4
        * circle_overlap_fraction(
            np.hypot(*_lenslet(optics, -1, -1).u), optics.subaperture_radius, optics.source_radius
        )
        * (optics.subaperture_radius / optics.source_radius) ** 2
    )
    assert total == pytest.approx(exact, rel=2e-3)
    zs = dpc_transfer_functions(optics, z_um=[-30.0, 0.0, 30.0])
    assert zs["dpc_phase"]["lr"].shape == (3, 145, 145)
    np.testing.assert_allclose(zs["dpc_phase"]["lr"][1], d["dpc_phase"]["lr"], atol=1e-6)


# ---------------------------------------------------------------- Abbe simulation
def _abbe_images(optics, obj, dx, sources, pupils, halves, z, norm):
    """Images of the halves by a sum over source points: each plane wave exp(i2π w·x) through
    the object, the pupil (or lenslet sub-aperture) and the defocus, |.|² summed (paper Eq. 2)."""
    n = obj.shape[0]
    spec = sfft.fft2(obj)
    ux, uy = _grid(n, 1.0 / (n * dx))
    defocus = np.exp(2j * np.pi * z * axial_frequency(ux, uy, optics))
    out = {h: np.zeros((n, n)) for h in set(halves.values())}
    for k, (s, p) in enumerate(zip(sources, pupils)):
        jy, jx = np.nonzero(s * p)  # a blocked direct beam gives dark field: second order, left out
        for y, x in zip(jy, jx):
            field = sfft.ifft2(np.roll(spec, (y, x), axis=(0, 1)) * p * defocus)
            out[halves[k]] += s[y, x] * np.abs(field) ** 2
    return {h: v / norm for h, v in out.items()}


@pytest.mark.parametrize("model", ["lenslet", "paper"])
@pytest.mark.parametrize("z", [0.0, 25.0])
def test_first_order_model_matches_abbe_simulation(optics, model, z):
    """(I_up − I_down)/(I_up + I_down) of a weak object, simulated source point by source point,
    equals F⁻¹[H_DPC,phase φ̃ − H_DPC,abs μ̃] (sign conventions of the module docstring)."""
    n, m = 128, 8  # du = 0.128205/m puts every u_k on the frequency grid
    du = 1.0 / (optics.wavelength_um * optics.f_obj_um * optics.m_r) * optics.lenslet_radius_um / m
    dx = 1.0 / (n * du)
    ux, uy = _grid(n, du)
    r = np.hypot(ux, uy)
    source = (r <= optics.source_radius).astype(float)
    objective = r <= optics.cutoff
    if model == "lenslet":
        lens = [ln for ln in nominal_lenslets(optics) if lenslet_case(optics, ln) != "outside" and ln.a_um[1] != 0]
        pupils = [
            (objective & (np.hypot(ux - ln.u[0], uy - ln.u[1]) <= optics.subaperture_radius)).astype(float)
            for ln in lens
        ]
        halves = {k: ("up" if ln.a_um[1] < 0 else "down") for k, ln in enumerate(lens)}
        sources = [source] * len(lens)
    else:
        pupils = [objective.astype(float)] * 2
        halves = {0: "up", 1: "down"}
        sources = [source * (uy > 0) + 0.5 * source * (uy == 0), source * (uy < 0) + 0.5 * source * (uy == 0)]
    rng = np.random.default_rng(7)
    phi = 1e-3 * rng.standard_normal((n, n))
    mu = 5e-4 * rng.standard_normal((n, n))
    obj = np.exp(-mu + 1j * phi)
    eta = axial_frequency(ux, uy, optics)
    images = _abbe_images(optics, obj, dx, sources, pupils, halves, z, source.sum())
    dpc_sim = (images["up"] - images["down"]) / (images["up"] + images["down"])
    tf = {"up": [0, 0, 0.0], "down": [0, 0, 0.0]}
    for k, h in halves.items():
        h_abs, h_phase = weak_object_transfer_functions(sources[k], pupils[k], z, eta, norm=source.sum())
        tf[h][0] = tf[h][0] + h_abs
        tf[h][1] = tf[h][1] + h_phase
        tf[h][2] += h_abs[0, 0].real / 2
    h_dpc_abs = dpc_from_halves(tf["up"][0], tf["down"][0], tf["up"][2], tf["down"][2])
    h_dpc_phase = dpc_from_halves(tf["up"][1], tf["down"][1], tf["up"][2], tf["down"][2])
    pred = sfft.ifft2(h_dpc_phase * sfft.fft2(phi) - h_dpc_abs * sfft.fft2(mu)).real
    assert np.abs(pred).max() > 1e-4  # a real signal, not two zeros
    assert np.linalg.norm(dpc_sim - pred) / np.linalg.norm(dpc_sim) < 0.01


def test_bad_input(optics):
    from napari_ssdpc.errors import SsdpcError

    with pytest.raises(SsdpcError, match="share one 2D"):
        weak_object_transfer_functions(np.ones((8, 8)), np.ones((8, 9)))
    with pytest.raises(SsdpcError, match="eta"):
        weak_object_transfer_functions(np.ones((8, 8)), np.ones((8, 8)), z_um=5.0)
    with pytest.raises(SsdpcError, match="source is empty"):
        weak_object_transfer_functions(np.zeros((8, 8)), np.ones((8, 8)))
    with pytest.raises(SsdpcError, match="unknown transfer model"):
        dpc_transfer_functions(optics, model="tian")
    with pytest.raises(SsdpcError, match="condenser_na is 0"):
        dpc_transfer_functions(optics.replace(condenser_na=0.0))
    with pytest.raises(SsdpcError, match="no direct light"):  # source inside the gap at the vertex
        dpc_transfer_functions(optics.replace(condenser_na=0.02))
