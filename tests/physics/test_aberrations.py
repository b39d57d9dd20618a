"""The instrument's aberrations: Zernike terms of the objective and each lenslet's own sub-aperture,
in the one Pupil every model samples (docs/aberrations.md)."""

import json
import math

import numpy as np
import pytest

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.psf import LensletPSF
from napari_ssdpc.physics.psf_reference import reference_psf
from napari_ssdpc.physics.pupil import Pupil, mean_tilt, subaperture_pupil
from napari_ssdpc.physics.transfer import lenslet_transfer_functions
from napari_ssdpc.physics.zernike import noll_to_nm, zernike
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.settings.optics import Optics

SPHERICAL = (0, 0, 0, 0, 0.2, 0, 0.3, 0, 0, 0, 0.5)  # astigmatism, coma and spherical aberration, waves rms


@pytest.fixture(scope="module")
def optics():
    return Optics.paper()


def _two(optics):
    """A central lenslet and one clipped by the objective's edge."""
    return [ln for ln in nominal_lenslets(optics) if (ln.row, ln.col) in ((-1, -1), (1, 2))]


# ------------------------------------------------------------------------------ Zernike
def test_noll_indices_are_the_standard_ones():
    expected = {1: (0, 0), 2: (1, 1), 3: (1, -1), 4: (2, 0), 5: (2, -2), 6: (2, 2), 7: (3, -1), 8: (3, 1)}
    expected.update({11: (4, 0), 12: (4, 2), 15: (4, -4), 22: (6, 0)})
    assert {j: noll_to_nm(j) for j in expected} == expected
    with pytest.raises(SsdpcError, match="Noll index"):
        noll_to_nm(0)


def test_zernike_polynomials_are_orthonormal_over_the_pupil():
    """∫ Z_i Z_j / π over the unit disk = δ_ij (Noll's normalisation: a coefficient is the rms)."""
    t = (np.arange(400) + 0.5) / 200 - 1
    x, y = np.meshgrid(t, t)
    r, theta = np.hypot(x, y), np.arctan2(y, x)
    inside = r <= 1
    z = np.array([zernike(j, r[inside], theta[inside]) for j in range(1, 16)])
    gram = z @ z.T / inside.sum()
    np.testing.assert_allclose(gram, np.eye(15), atol=5e-3)
    # spherical aberration is 6√5 r⁴ − 6√5 r² + √5
    assert zernike(11, np.array(0.5), np.array(0.0)) == pytest.approx(math.sqrt(5) * (6 / 16 - 6 / 4 + 1))


# ------------------------------------------------------------------------------ settings
def test_all_zero_is_the_nominal_instrument_and_is_not_written(optics):
    zero = optics.replace(
        aberrations=Aberrations(objective_zernike_waves=(0.0,) * 11, lenslets=(LensletTerms(row=-1, col=-1),))
    )
    assert not Pupil.of(zero).aberrated and Pupil.of(zero) == Pupil.of(optics)
    assert "aberrations" not in zero.to_dict()
    lenslets = _two(optics)
    a = LensletPSF(optics, lenslets).kernels(20.0)
    b = LensletPSF(zero, lenslets).kernels(20.0)
    assert a.dtype == b.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    for x, y in zip(
        lenslet_transfer_functions(optics, lenslets, (32, 32), optics.object_pixel_um, [0.0, 5.0]),
        lenslet_transfer_functions(zero, lenslets, (32, 32), optics.object_pixel_um, [0.0, 5.0]),
    ):
        np.testing.assert_array_equal(x, y)


def test_aberrations_travel_with_the_optics(optics, tmp_path):
    ab = Aberrations(
        objective_zernike_waves=SPHERICAL,
        lenslets=(LensletTerms(row=1, col=2, offset_um=(2.0, -1.0), radius_scale=0.98, defocus_waves=-0.3),),
    )
    o = optics.replace(aberrations=ab)
    back = Optics.from_dict(json.loads(json.dumps(o.to_dict())))
    assert back == o and back.aberrations.lenslet(1, 2).defocus_waves == -0.3
    assert back.aberrations.lenslet(0, 0).is_nominal
    o.to_yaml(tmp_path / "optics.yaml")
    assert Optics.from_yaml(tmp_path / "optics.yaml") == o


@pytest.mark.parametrize(
    "aberrations, words",
    [
        ({"objective_zernike_waves": [0.0, "0.5"]}, "objective_zernike_waves"),
        ({"objective_zernike_waves": [0.0, 12.0]}, "at most ±10 is modelled"),
        ({"lenslets": [{"row": 0, "col": 0}, {"row": 0, "col": 0}]}, "named twice"),
        ({"lenslets": [{"row": 0, "col": 0, "radius_scale": 2.0}]}, "radius_scale"),
        ({"lenslets": [{"row": 0, "col": 0, "defocus_wave": 0.1}]}, "defocus_waves"),
    ],
)
def test_bad_aberrations_are_one_line(optics, aberrations, words):
    with pytest.raises(SsdpcError, match=words) as err:
        Optics.from_dict({**optics.to_dict(), "aberrations": aberrations})
    assert "\n" not in str(err.value)


# ------------------------------------------------------------------------------ physics
def test_the_fast_psf_matches_the_eq6_reference_with_an_aberrated_objective(optics):
    """The full Eq. 6 PSF (the pupil field imaged onto the MLA, every lenslet's phase, Fresnel
    propagation to the sensor) and the per-lenslet fast form, both with the objective's phase: they
    agree within 1% where the aberration changes the kernels by more than 100%."""
    aberrated = optics.replace(aberrations=Aberrations(objective_zernike_waves=SPHERICAL))
    lenslets = _two(optics)
    ref = reference_psf(aberrated, lenslets, (-30.0, 30.0))
    fast, ideal = LensletPSF(aberrated, lenslets), LensletPSF(optics, lenslets)
    windows, fast.offsets_px = ref.windows(fast.shape)
    ideal.offsets_px = fast.offsets_px
    for i, z in enumerate((-30.0, 30.0)):
        k, r = fast.kernels(z).reshape(2, -1), windows[i].reshape(2, -1)
        err = np.linalg.norm(k - r, axis=1) / np.linalg.norm(r, axis=1)
        assert err.max() < 0.01, err  # measured 0.0017-0.0064 (nominal optics: 0.0005-0.0012)
        change = np.linalg.norm(ideal.kernels(z).reshape(2, -1) - r) / np.linalg.norm(r)
        assert change > 1.0  # measured 1.25-1.30


def test_a_lenslet_defocus_is_a_shift_of_its_focus(optics):
    """d waves at the sub-aperture's edge is the paraxial defocus z = −2 n d / (λ ρ²): a lenslet
    defocused by 0.5 waves sees at z = 0 what the nominal one sees at −178 µm (within 1% L2), and
    nothing like what it sees at ±10% of that depth."""
    ln = _two(optics)[0]
    d = 0.5
    shifted = optics.replace(aberrations=Aberrations(lenslets=(LensletTerms(row=ln.row, col=ln.col, defocus_waves=d),)))
    z_eq = -2 * optics.medium_index * d / (optics.wavelength_um * optics.subaperture_radius**2)
    blur = LensletPSF(shifted, [ln])._compute_blur(0.0)[0]
    nominal = LensletPSF(optics, [ln])
    depths = z_eq * np.array([1, 0.9, 1.1])
    err = [np.linalg.norm(blur - nominal._compute_blur(z)[0]) / np.linalg.norm(blur) for z in depths]
    assert err[0] < 0.01  # measured 0.008
    assert min(err[1:]) > 0.05  # measured 0.07-0.10


def test_a_lenslets_own_centre_and_radius_are_its_sub_aperture(optics):
    """A sub-aperture 3 % wider passes 1.03² of the light and moved off centre tilts its view: the
    soft-edged grid (transfer functions, PSF) and the cell fractions (simulator) sample the same."""
    from napari_ssdpc.physics.apertures import subaperture_windows

    ln = _two(optics)[0]  # inside the objective's pupil
    terms = LensletTerms(row=ln.row, col=ln.col, offset_um=(40.0, 0.0), radius_scale=1.03)
    o = optics.replace(aberrations=Aberrations(lenslets=(terms,)))
    pupil = Pupil.of(o)
    u_k, rho_k, _ = pupil.lenslet(ln)
    shift = -40.0 / (o.wavelength_um * o.f_obj_um * o.m_r)  # u = −a / (λ f_obj m_r)
    assert u_k == pytest.approx((ln.u[0] + shift, ln.u[1]))
    assert rho_k == pytest.approx(1.03 * o.subaperture_radius)
    du = rho_k / 40
    soft, ux, uy = subaperture_pupil(o, ln, (128, 128), du)
    _, cells = subaperture_windows([ln], pupil, du, 128)
    full = math.pi * o.subaperture_radius**2
    assert soft.sum() * du**2 == pytest.approx(1.03**2 * full, rel=2e-3)
    assert (cells[0] ** 2).sum() * du**2 == pytest.approx(1.03**2 * full, rel=2e-3)
    nominal, nx, ny = subaperture_pupil(optics, ln, (128, 128), du)
    tilt, tilt0 = mean_tilt(o, soft, ux, uy), mean_tilt(optics, nominal, nx, ny)
    # the view's parallax follows its sub-aperture's centre: tanθ = λ u / n for small angles
    assert tilt[0] - tilt0[0] == pytest.approx(o.wavelength_um * shift / o.medium_index, rel=0.05)


def test_the_summary_names_the_terms(optics):
    assert optics.aberrations.summary() == "aberrations: none (the nominal optics)"
    ab = Aberrations(objective_zernike_waves=SPHERICAL, lenslets=(LensletTerms(row=0, col=0, defocus_waves=-0.25),))
    text = ab.summary()
    assert "Z11 +0.500" in text and "Z5 +0.200" in text and "Z4" not in text
    assert "1 lenslet differs (defocus up to 0.250 waves" in text


def test_an_off_axis_condenser_lights_the_lenslets_it_overlaps(optics):
    """The direct light of each view is the area of the condenser disk inside the lenslet's own
    sub-aperture: with the disk 0.03 NA off axis and a lenslet 5 % wider, in the multislice model and
    in the transfer functions alike (within 1 % and 0.5 %), where the nominal areas are up to 30 % off."""
    from napari_ssdpc.physics.views_multislice import ViewsMultislice
    from napari_ssdpc.settings.lenslets import circle_overlap_fraction

    base = optics.replace(condenser_na=0.3)
    ab = Aberrations(condenser_offset_na=(0.03, -0.02), lenslets=(LensletTerms(row=-1, col=0, radius_scale=1.05),))
    o = base.replace(aberrations=ab)
    assert o.source_centre == pytest.approx((0.03 / o.wavelength_um, -0.02 / o.wavelength_um))
    inside = [ln for ln in nominal_lenslets(o) if ln.fraction == 1.0]
    u_k, rho_k, _ = Pupil.of(o).lenslet_arrays(inside)
    area = circle_overlap_fraction(np.hypot(*(u_k - o.source_centre).T), rho_k, o.source_radius) * rho_k**2
    lit = area > 0.05 * area.max()
    area = area[lit] / area[lit].max()
    inside = [ln for ln, keep in zip(inside, lit) if keep]
    nominal = circle_overlap_fraction(
        np.hypot(*np.array([ln.u for ln in inside]).T), o.subaperture_radius, o.source_radius
    )
    assert np.abs(nominal / nominal.max() - area).max() > 0.1  # measured 0.3
    x = (np.arange(32) - 15.5) * o.object_pixel_um
    model = ViewsMultislice(o, inside, x, x, [0.0], dz_um=1.0, source_spacing_na=0.03)
    assert np.abs(model.i0 / model.i0.max() / area - 1).max() < 0.01  # measured 0.004
    # the transfer functions' soft-edged sub-apertures on a grid fine enough for 0.2 % areas (32 px: 1.7 %)
    _, _, i0 = lenslet_transfer_functions(o, inside, (128, 128), o.object_pixel_um)
    assert np.abs(i0 / i0.max() / area - 1).max() < 0.005  # measured 0.0016


def test_the_pupil_gradient_matches_finite_differences():
    """∂misfit/∂(Zernike coefficient) and ∂misfit/∂(lenslet defocus) of the multislice model against
    central differences of models built with the terms moved (the basis of fitting them)."""
    from napari_ssdpc.physics.views_multislice import ViewsMultislice

    base = Optics.paper().replace(condenser_na=0.3)
    x = (np.arange(16) - 7.5) * base.object_pixel_um
    every = nominal_lenslets(base)
    _, _, i0 = lenslet_transfer_functions(base, every, (16, 16), base.object_pixel_um)
    lenslets = [ln for ln, i in zip(every, i0) if i >= 0.05 * max(i0)][::3]
    key = (lenslets[1].row, lenslets[1].col)
    start = {"c7": 0.1, "c11": 0.2, "d": 0.1}

    def model(**terms):
        t = {**start, **terms}
        ab = Aberrations(
            objective_zernike_waves=(0,) * 6 + (t["c7"], 0, 0, 0, t["c11"]),
            lenslets=(LensletTerms(row=key[0], col=key[1], defocus_waves=t["d"]),),
        )
        o = base.replace(aberrations=ab)
        return ViewsMultislice(o, lenslets, x, x, [-2.0, 0.0, 2.0], source_spacing_na=0.1, dtype=np.complex128)

    rng = np.random.default_rng(3)
    m0 = model()
    dn = 0.03 * rng.standard_normal(m0.shape)
    data = 1 + 0.1 * rng.standard_normal(m0.view_shape)
    weight = rng.uniform(0.5, 1.5, m0.view_shape)
    value, gz, gd = m0.pupil_misfit(dn, data, weight, noll=(7, 11))
    assert value == pytest.approx(m0.misfit(dn, data, weight)[0], rel=1e-12)
    eps = 1e-4

    def central(name):
        up, down = model(**{name: start[name] + eps}), model(**{name: start[name] - eps})
        return (up.misfit(dn, data, weight)[0] - down.misfit(dn, data, weight)[0]) / (2 * eps)

    assert gz[0] == pytest.approx(central("c7"), rel=1e-5)
    assert gz[1] == pytest.approx(central("c11"), rel=1e-5)
    assert gd[1] == pytest.approx(central("d"), rel=1e-5)
    assert np.count_nonzero(gd) == len(lenslets)  # every lenslet's defocus moves the misfit
    # one pass for both: the same numbers as the two calls
    both = m0.misfit_and_pupil(dn, data, weight, noll=(7, 11))
    assert both[0] == pytest.approx(value, rel=1e-12)
    np.testing.assert_allclose(both[1], m0.misfit(dn, data, weight)[1], rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(both[2], gz, rtol=1e-10)
    np.testing.assert_allclose(both[3], gd, rtol=1e-10)
    # the phase set on a model built nominal: the model built with those terms
    other = {"c7": -0.05, "c11": 0.3, "d": -0.2}
    moved = ViewsMultislice(base, lenslets, x, x, [-2.0, 0.0, 2.0], source_spacing_na=0.1, dtype=np.complex128)
    defocus = np.zeros(len(lenslets))
    defocus[1] = other["d"]
    moved.set_pupil_phase((0,) * 6 + (other["c7"], 0, 0, 0, other["c11"]), defocus)
    np.testing.assert_allclose(moved.views(dn), model(**other).views(dn), rtol=1e-12)


def test_the_objectives_aberration_leaves_the_field_stops_image_alone(optics):
    """Without a sample every plane wave only takes a constant phase at the objective's pupil, before
    the field stop: the white frame is the nominal one, while a lenslet's own defocus blurs its EI."""
    from napari_ssdpc.simulation.camera import Camera
    from napari_ssdpc.simulation.sample_free import white_intensity

    camera = Camera(noise=False)
    nominal = white_intensity(optics, camera=camera)
    objective = optics.replace(aberrations=Aberrations(objective_zernike_waves=SPHERICAL))
    np.testing.assert_array_equal(white_intensity(objective, camera=camera), nominal)
    ln = _two(optics)[0]
    lenslet = optics.replace(
        aberrations=Aberrations(lenslets=(LensletTerms(row=ln.row, col=ln.col, defocus_waves=0.5),))
    )
    assert np.abs(white_intensity(lenslet, camera=camera) - nominal).max() > 0.05 * nominal.max()
