"""Tests of the forward simulator (simulation/: simulate, multislice, imaging, sample_free, phantoms, camera).

Most tests use the paper's optics with a smaller iris (field radius 30 µm instead of
61.3 µm) so that a simulation takes seconds; the optics of the lens train, the
lenslet grid and the sensor are the paper's.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import mla_to_frequency, nominal_lenslets, tan_theta
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.physics.waves import propagate
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.camera import Camera
from napari_ssdpc.simulation.moving import moving_sample
from napari_ssdpc.simulation.multislice import Sampling, Source, exit_field
from napari_ssdpc.simulation.phantom_base import Composite
from napari_ssdpc.simulation.phantoms import (
    Sphere,
    Spheres,
    bar_target,
    cell,
    pmma_bead,
    two_beads,
)
from napari_ssdpc.simulation.primitives import Box
from napari_ssdpc.simulation.sample_free import flat_frame, flat_intensity, white_frame, white_intensity
from napari_ssdpc.simulation.simulate import effective_tan_theta, simulate

CLEAN = Camera(noise=False, falloff=0.0)


@pytest.fixture(scope="module")
def small():
    """Paper optics with a 30 µm field radius (iris 600 µm at the NIP)."""
    return Optics.paper().replace(iris_radius_um=600.0)


@pytest.fixture(scope="module")
def small_flat(small):
    return flat_intensity(small, camera=CLEAN)


def _obj_px(optics):
    return optics.pixel_um / optics.m_ei


def _centroid(img, start, optics, r0_um, r1_um, iters=8):
    """Centroid of |img| in a disk, re-centred on the previous estimate."""
    p = np.asarray(start, float)
    c = np.rint(p).astype(int)
    Y, X = np.mgrid[c[1] - 50 : c[1] + 51, c[0] - 50 : c[0] + 51]
    w0 = np.abs(img[Y, X])
    for r in [r0_um] + [r1_um] * iters:
        w = w0 * (np.hypot(X - p[0], Y - p[1]) <= r / _obj_px(optics))
        p = np.array([(w * X).sum(), (w * Y).sum()]) / w.sum()
    return p


# ------------------------------------------------------------------------------ camera
def test_camera_dark_offset_noise_and_saturation():
    cam = Camera(seed=1)
    dark = cam.apply(np.zeros((400, 400)))
    assert dark.dtype == np.uint16
    assert abs(dark.mean() - 100.0) < 0.01
    assert abs(dark.std() - math.sqrt((2.5 * 0.25) ** 2 + 1 / 12)) < 0.01  # read noise + rounding, ADU
    half = cam.apply(np.full((400, 400), 0.5)).astype(float)
    assert abs(half.mean() - (100 + 0.5 * 12000 * 0.25)) < 0.2
    expect_std = math.sqrt(0.25**2 * (0.5 * 12000 + 2.5**2) + 1 / 12)  # shot + read noise + rounding
    assert abs(half.std() / expect_std - 1) < 0.02
    sat = cam.apply(np.full((50, 50), 1.4))  # 16800 e-: above the ADC range
    assert np.all(sat == 4095)
    well = Camera(noise=False, full_well_e=10000.0).apply(np.array([0.8, 2.0]))
    assert list(well) == [round(0.8 * 12000 * 0.25 + 100), round(10000 * 0.25 + 100)]
    assert np.array_equal(Camera(noise=False).apply(np.array([0.0, 1.0])), [100, 3100])
    a, b = Camera(seed=7).apply(np.ones((8, 8))), Camera(seed=7).apply(np.ones((8, 8)))
    assert np.array_equal(a, b)
    with pytest.raises(SsdpcError):
        Camera(falloff=1.5)


# --------------------------------------------------------------------- white and flat
def _overlap_fraction_mc(u_k, rho, cut, n=1600):
    """Fraction of the sub-aperture inside the pupil on a fine grid (independent check)."""
    t = (np.arange(n) + 0.5) / n * 2 * rho - rho
    ux, uy = np.meshgrid(u_k[0] + t, u_k[1] + t)
    sub = (ux - u_k[0]) ** 2 + (uy - u_k[1]) ** 2 <= rho * rho
    return np.count_nonzero(sub & (ux * ux + uy * uy <= cut * cut)) / np.count_nonzero(sub)


@pytest.mark.parametrize("offset_px", [(0.0, 0.0), (11.3, -6.8)])
def test_white_frame_edge_brightness_is_exact_overlap(offset_px):
    o = Optics.paper()
    g = Grid.nominal(o, axis_offset_px=offset_px)
    img = white_intensity(o, g, camera=CLEAN)
    lens = g.lenslets(o)
    assert len(lens) >= 32
    errs = []
    for ln in lens:
        c = g.lattice_px(ln.row, ln.col)
        ix, iy = int(round(c[0])), int(round(c[1]))
        val = img[iy - 1 : iy + 1 + 1, ix - 1 : ix + 2].mean()  # 3x3 px at the EI centre
        ref = _overlap_fraction_mc(ln.u, o.subaperture_radius, o.cutoff)
        errs.append(val - ref)
    errs = np.abs(errs)
    # plateau flat to ~1e-4 near the centre; Monte-Carlo reference good to ~1e-3
    assert errs.max() < 2e-3, errs.max()
    # the EI is the iris disk: half maximum at R_EI = 72.46 px, upward from a top-row EI
    ln = min((ln for ln in lens if ln.fraction > 0.5), key=lambda ln: (ln.row, -ln.fraction))
    c = g.lattice_px(ln.row, ln.col)
    col = img[:, int(round(c[0]))]
    y = c[1] - np.arange(len(col))  # distance above the centre
    up = (y > 40) & (y < 100)
    r_half = np.interp(-0.5 * ln.fraction, -col[up][::-1], y[up][::-1])
    assert abs(r_half - o.ei_radius_px) < 0.5, r_half


def test_white_frame_raw_and_falloff():
    o = Optics.paper()
    raw = white_frame(o, rng=3)
    assert raw.dtype == np.uint16 and raw.shape == (o.height_px, o.width_px)
    g = Grid.nominal(o)
    img = white_intensity(o, g, camera=Camera(falloff=0.15))
    ln = next(ln for ln in g.lenslets(o) if ln.fraction == 1.0)
    c = g.lattice_px(ln.row, ln.col)
    r_px = 0.8 * o.field_radius_um / _obj_px(o)
    centre = img[int(round(c[1])), int(round(c[0]))]
    edge = img[int(round(c[1])), int(round(c[0] + r_px))]
    assert abs(edge / centre - (1 - 0.15 * 0.8**2)) < 5e-3


def test_flat_frame_lights_only_central_lenslets():
    o = Optics.paper()  # σ = 0.25
    g = Grid.nominal(o)
    cam = Camera(noise=False, falloff=0.0)
    raw = flat_frame(o, g, camera=cam)
    assert raw.dtype == np.uint16 and raw.shape == (o.height_px, o.width_px)
    img = (raw.astype(float) - cam.dark_offset_adu) / (cam.gain_adu_per_e * cam.exposure_e)
    lit, dark = [], []
    for ln in g.lenslets(o):
        c = np.rint(g.lattice_px(ln.row, ln.col)).astype(int)
        v = img[c[1] - 2 : c[1] + 3, c[0] - 2 : c[0] + 3].mean()
        (lit if max(abs(ln.a_um[0]), abs(ln.a_um[1])) < o.pitch_um else dark).append(v)
    assert len(lit) == 4 and len(dark) == 28
    # partly lit: source ∩ sub-aperture is 48.1 % of the sub-aperture (0.472 simulated)
    assert min(lit) > 0.45 and max(lit) < 0.49
    assert max(dark) < 1e-3


def test_flat_field_cancels_unscattered_light(small, small_flat):
    empty = simulate(None, small, camera=CLEAN)
    assert np.allclose(empty.intensity, small_flat, rtol=0, atol=1e-9)
    sim = simulate(Sphere((8.0, -5.0, 0.0), 3.0, 1.518 + 0.01j, medium_index=1.518), small, camera=CLEAN)
    g, s = sim.grid, _obj_px(small)
    c = g.lattice_px(0, 0)
    Y, X = np.mgrid[int(c[1]) - 40 : int(c[1]) + 41, int(c[0]) - 40 : int(c[0]) + 41]
    ox, oy = (X - c[0]) * s, (Y - c[1]) * s
    far = (np.hypot(ox - 8.0, oy + 5.0) > 20.0) & (np.hypot(ox, oy) < 20.0)
    ratio = sim.intensity[Y, X][far] / small_flat[Y, X][far]
    assert np.abs(ratio - 1).max() < 2e-4  # measured 7e-5


# --------------------------------------------------------------------------- physics
@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.15, -0.1)])
def test_propagator_conserves_energy(tilt):
    n, dx = 256, 0.3
    x = (np.arange(n) - n / 2) * dx
    X, Y = np.meshgrid(x, x)
    f = (np.exp(-(X**2 + Y**2) / (2 * 3.0**2)) * np.exp(2j * np.pi * 0.3 * X)).astype(np.complex64)
    e0 = np.sum(np.abs(f.astype(np.complex128)) ** 2)
    for d in (50.0, -30.0):
        g = propagate(f, d, dx, 0.52, 1.518, tilt)
        assert g.dtype == np.complex64
        e1 = np.sum(np.abs(g.astype(np.complex128)) ** 2)
        assert abs(e1 - e0) / e0 < 1e-6
        assert np.abs(g - f).max() > 0.1  # it did propagate


def test_propagator_defocus_matches_gaussian_beam():
    """A Gaussian beam of waist w0 spreads to w0 sqrt(1 + (z/zR)²), zR = π w0² n / λ."""
    n, dx, lam, nm, w0 = 512, 0.25, 0.52, 1.518, 1.5
    x = (np.arange(n) - n / 2) * dx
    X, Y = np.meshgrid(x, x)
    f = np.exp(-(X**2 + Y**2) / w0**2).astype(np.complex128)
    z = 20.0
    g = np.abs(propagate(f, z, dx, lam, nm)) ** 2
    w_meas = 2 * math.sqrt((g * X**2).sum() / g.sum())  # 1/e² radius from the 2nd moment
    zr = math.pi * w0**2 * nm / lam
    assert abs(w_meas / (w0 * math.sqrt(1 + (z / zr) ** 2)) - 1) < 0.02


@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.15, 0.05)])
def test_thin_phase_plate_phase(tilt):
    o = Optics.paper()
    t, dn = 1.0, 0.01 + 0.002j
    plate = Composite((Box((0.0, 0.0, 0.0), (40.0, 40.0, t), dn),), medium_index=1.518)
    v, z_exit, samp = exit_field(plate, o, tilt=tilt)
    phase = np.angle(v[0, 0])  # x = y = 0 (FFT order)
    expect = 2 * math.pi * dn.real * t / o.wavelength_um  # 0.1208 rad
    assert abs(phase / expect - 1) < 1e-3, phase
    assert abs(abs(v[0, 0]) / math.exp(-2 * math.pi * dn.imag * t / o.wavelength_um) - 1) < 1e-4
    assert abs(v[samp.n // 2, samp.n // 2] - 1) < 1e-6  # far outside: unperturbed


def test_abcd_lens_train_sign_and_upright_ei():
    """Paraxial ray trace objective -> tube lens -> Fourier lens -> MLA -> sensor (1D)."""
    o = Optics.paper()

    def P(d):
        return np.array([[1.0, d], [0.0, 1.0]])

    def L(f):
        return np.array([[1.0, 0.0], [-1.0 / f, 1.0]])

    f_obj, f_tube, f_fl, f_ml = o.f_obj_um, o.tube_lens_mm * 1e3, o.fourier_lens_mm * 1e3, o.mla_focal_length_mm * 1e3
    to_mla = P(f_fl) @ L(f_fl) @ P(f_fl) @ P(f_tube) @ L(f_tube) @ P(f_tube) @ P(f_obj) @ L(f_obj) @ P(f_obj)
    for na in (0.05, -0.12, 0.3):  # reduced angle n sinθ = λ u
        a, _ = to_mla @ np.array([0.0, na])
        u = na / o.wavelength_um
        assert math.isclose(float(mla_to_frequency(o, a)), u, rel_tol=1e-9)
        assert math.isclose(a, -u * o.wavelength_um * f_obj * o.m_r, rel_tol=1e-9)
    # a point at x0 in focus: every ray through the lenslet centred at a_c lands at a_c + x0·M_EI
    x0, a_c = 7.0, 750.0
    hits = []
    for na in np.linspace(-0.02, 0.02, 5):
        y = to_mla @ np.array([x0, na - a_c / (f_obj * o.m_r)])
        y = P(f_ml) @ (L(f_ml) @ np.array([y[0] - a_c, y[1]]))  # lenslet about its own centre
        hits.append(y[0])
    assert np.ptp(hits) < 1e-9  # imaged (sensor at the MLA focus)
    assert math.isclose(hits[0], x0 * o.m_ei, rel_tol=1e-9)  # upright, magnification M_EI


def test_effective_tan_theta_is_below_centre_for_clipped_lenslets():
    o = Optics.paper()
    for ln in nominal_lenslets(o):
        ratio = np.linalg.norm(effective_tan_theta(o, ln)) / tan_theta(o, np.array(ln.u))[0]
        if ln.fraction < 0.6:
            assert 0.92 < ratio < 0.95  # ~6 % below the centre value
        if ln.fraction == 1.0:
            assert abs(ratio - 1) < 2e-3
        t = effective_tan_theta(o, ln)
        assert np.dot(t, ln.u) > 0  # along u_k, i.e. against a


def test_in_focus_positions_follow_grid_matrix(small, small_flat):
    """An in-focus bead at (8, -5) µm sits at grid.object_to_sensor in every EI."""
    g = Grid(Grid.nominal(small).axis_px, Grid.nominal(small).vertex_px, small.pitch_px, -2.0, True, False)
    flat = flat_intensity(small, g, camera=CLEAN)
    sim = simulate(Sphere((8.0, -5.0, 0.0), 3.0, 1.518 + 0.01j, medium_index=1.518), small, g, camera=CLEAN)
    errs = []
    for ln in sim.lenslets:
        exp = g.object_to_sensor(ln, (8.0, -5.0), small)
        errs.append(np.linalg.norm(_centroid(sim.intensity - flat, exp, small, 8.0, 8.0) - exp))
    assert max(errs) < 0.3, max(errs)  # measured 0.14 px


def _df_weighted_tan(optics, ln, radius_um, kappa, d=0.006):
    """First-order prediction for a dark-field EI: the centroid of |scattered field|² moves by
    z times the mean of tanθ(u)·û(u) over u ∈ A_k and w ∈ source, weighted by |O(u − w)|²,
    O = 2D spectrum of the bead's projected amplitude change (first-moment theorem)."""
    from scipy import special

    lam, nm = optics.wavelength_um, optics.medium_index
    r = np.linspace(0.0, radius_um, 1500)
    ob = 1 - np.exp(-4 * np.pi * kappa * np.sqrt(radius_um**2 - r**2) / lam)
    fr = np.linspace(0.0, 2.0, 801)
    spec = np.trapezoid(ob[None, :] * special.j0(2 * np.pi * fr[:, None] * r[None, :]) * r[None, :], r, axis=1)
    g = np.arange(-1.0, 1.0, d)
    wx, wy = np.meshgrid(g, g)
    src = wx**2 + wy**2 <= optics.source_radius**2
    wx, wy = wx[src], wy[src]
    rho, cut = optics.subaperture_radius, optics.cutoff
    ux, uy = np.meshgrid(ln.u[0] + np.arange(-rho, rho, d), ln.u[1] + np.arange(-rho, rho, d))
    a = ((ux - ln.u[0]) ** 2 + (uy - ln.u[1]) ** 2 <= rho * rho) & (ux**2 + uy**2 <= cut * cut)
    ux, uy = ux[a], uy[a]
    k = lam / nm / np.sqrt(1 - (lam / nm) ** 2 * (ux**2 + uy**2))
    wgt = (np.interp(np.hypot(ux[:, None] - wx[None, :], uy[:, None] - wy[None, :]), fr, spec) ** 2).sum(axis=1)
    return np.array([np.sum(wgt * k * ux), np.sum(wgt * k * uy)]) / wgt.sum()


def test_defocused_bead_parallax(small, small_flat):
    """3 µm absorbing bead at z = ±30 µm: shift z·<tanθ>_k toward (z>0) / away from (z<0) the axis."""
    o, s = small, _obj_px(small)
    radius, kappa = 1.5, 0.01
    report = {}
    for z in (30.0, -30.0):
        sim = simulate(Sphere((0.0, 0.0, z), 2 * radius, 1.518 + 1j * kappa, medium_index=1.518), o, camera=CLEAN)
        g = sim.grid
        for ln in sim.lenslets:
            c = g.lattice_px(ln.row, ln.col)
            expect = z * effective_tan_theta(o, ln) / s
            meas = _centroid(sim.intensity - small_flat, c, o, 20.0, 8.0) - c
            centre_value = z * tan_theta(o, np.array(ln.u))[0] * np.asarray(ln.u) / np.linalg.norm(ln.u) / s
            report[(z, ln.row, ln.col)] = (ln, meas, expect, centre_value)
    # the brief's prediction, pupil-weighted <tanθ>_k, for the 16 outer EIs (|u_k| > 0.6 cycles/µm)
    outer = [k for k, v in report.items() if np.linalg.norm(v[0].u) > 0.6]
    assert len(outer) == 32  # 16 outer EIs x 2 depths
    for k in outer:
        ln, meas, expect, centre_value = report[k]
        assert np.linalg.norm(meas - expect) < 0.3, (k, meas, expect)  # measured <= 0.20 px
        if ln.fraction < 0.6:  # clipped EIs: the pupil-weighted value, not the centre value
            assert np.linalg.norm(meas - expect) < 0.5 * np.linalg.norm(meas - centre_value)
    # every EI: the bead moves toward the optical axis for z > 0, away for z < 0
    for (z, _, _), (ln, meas, _, _) in report.items():
        assert np.sign(-np.dot(meas, ln.a_um)) == np.sign(z)
    # dark-field EIs (one quadrant, by symmetry): the object-weighted first-order prediction
    for (z, row, col), (ln, meas, _, _) in report.items():
        if row >= 0 and col >= 0 and max(abs(ln.a_um[0]), abs(ln.a_um[1])) > o.pitch_um:
            pred = z * _df_weighted_tan(o, ln, radius, kappa) / s
            assert np.linalg.norm(meas - pred) < 0.2, ((z, row, col), meas, pred)  # measured <= 0.14 px


def test_source_sampling_converges(small):
    bead = Sphere((3.0, 2.0, 10.0), 4.0, 1.53, medium_index=1.518)
    imgs = {st: simulate(bead, small, camera=CLEAN, source=Source(step=st)).intensity for st in (4, 2, 1)}
    ref = np.linalg.norm(imgs[1])
    d42 = np.linalg.norm(imgs[4] - imgs[2]) / ref
    d21 = np.linalg.norm(imgs[2] - imgs[1]) / ref
    print(f"source sampling: change 4->2 {d42:.4f}, 2->1 {d21:.4f}")
    assert d21 < 0.5 * d42
    assert d21 < 0.01


def test_progress_and_medium_override(small):
    calls = []
    sim = simulate(cell(), small, camera=CLEAN, source=Source(step=4), progress=lambda d, n: calls.append((d, n)))
    assert sim.optics.medium_index == 1.33 and small.medium_index == 1.518
    assert calls[-1] == (sim.n_source_points, sim.n_source_points) and len(calls) == sim.n_source_points
    assert sim.frame.dtype == np.uint16 and sim.intensity.shape == (small.height_px, small.width_px)
    assert sim.phantom.medium_index == 1.33


def test_sampling_guards():
    o = Optics.paper()
    s = Sampling.for_optics(o)
    assert s.size_um >= o.fov_um + 30 and s.dx_um <= 0.3 and s.n % 2 == 0
    with pytest.raises(SsdpcError):
        Sampling.for_optics(o, dx_um=0.8)
    with pytest.raises(SsdpcError):
        Source(step=0)


# -------------------------------------------------------------------------- phantoms
def test_sphere_partial_volume_matches_analytic_volume():
    b = pmma_bead()
    x = np.arange(-8.0, 8.01, 0.4)
    z = np.arange(-8.0, 8.01, 0.5)
    vol = b.volume(z, x, x)
    total = vol.sum() * 0.4 * 0.4 * 0.5
    expect = (1.49 - 1.518) * 4 / 3 * math.pi * 6.5**3
    assert abs(total / expect - 1) < 2e-3
    assert abs(vol[len(z) // 2, len(x) // 2, len(x) // 2] - (1.49 - 1.518)) < 1e-12
    assert b.delta_n(0.0, 0.0, 6.4) == pytest.approx(1.49 - 1.518)
    assert b.delta_n(0.0, 0.0, 6.6) == 0
    edge = vol[len(z) // 2, len(x) // 2]
    assert np.any((np.abs(edge) > 0) & (np.abs(edge) < 0.99 * 0.028))  # partial-volume rim


def test_phantom_catalogue():
    tb = two_beads()
    assert tb.z_range() == (-28.0, 33.0)
    assert tb.delta_n(-25.0, 0.0, -20.0) == pytest.approx(1.56 - 1.518)
    assert tb.delta_n(30.0, 0.0, 20.0) == pytest.approx(1.56 - 1.518)
    c = cell()
    assert c.medium_index == 1.33
    cx, cy, cz = c.center_um
    nx, ny, nz = c.nucleus_offset_um
    assert c.delta_n(cz + nz, cy + ny, cx + nx) == pytest.approx(1.39 - 1.33)
    assert c.delta_n(cz, cy, cx - 10.0) == pytest.approx(1.37 - 1.33)
    t = bar_target(period_um=4.38, z_um=40.0)
    xy = np.arange(-20, 20, 0.1)
    proj = t.slab(39.0, 41.0, xy, xy, 0.1)  # ∫ Δn dz through the target
    # bars transmit 10 % of the intensity
    assert math.isclose(math.exp(-4 * math.pi * proj.imag.max() / 0.52), 0.1, rel_tol=1e-6)
    covered = proj.imag.sum() * 0.01 / proj.imag.max()  # exact partial-pixel areas
    assert abs(covered - 6 * 2.19 * 10.95) < 1e-6  # 6 bars of 2.19 x 10.95 µm
    frames = moving_sample(5)
    xs = [f.center_um[0] for f in frames]
    assert len(frames) == 5 and xs[0] == -35.0 and xs[-1] == 35.0 and np.all(np.diff(xs) > 0)
    with pytest.raises(SsdpcError):
        Sphere().delta_n(0, 0, 0)  # no medium bound
    assert Sphere().delta_n(0, 0, 0, medium_index=1.518) == pytest.approx(1.49 - 1.518)
    assert isinstance(Spheres([Sphere()]).spheres, tuple)


# ------------------------------------------------------------------------------ slow
@pytest.mark.slow
def test_pmma_bead_run_time_paper_optics():
    o = Optics.paper()
    t = time.perf_counter()
    sim = simulate(pmma_bead(), o, camera=Camera(seed=0))
    dt = time.perf_counter() - t
    print(f"PMMA bead, paper optics: {dt:.1f} s, {sim.n_source_points} source points, {sim.info}")
    flat = flat_intensity(o, sim.grid, camera=sim.camera)
    c = sim.grid.lattice_px(0, 0)
    ratio = sim.intensity[int(c[1]), int(c[0])] / flat[int(c[1]), int(c[0])]
    assert 0.0 < ratio < 2.0 and sim.frame.max() < 4095


def test_the_temporal_prior_phantoms_move_and_change_as_documented():
    from napari_ssdpc.simulation import moving

    glide = moving.gliding_cell_and_bead(10)
    cells = np.array([p.items[0].center_um for p in glide])
    assert np.allclose(np.diff(cells, axis=0), (2.0, 4 / 3, 4 / 3))  # µm a frame in x, y, z
    assert all(p.items[2] == glide[0].items[2] for p in glide)  # the bead rests
    assert glide[0].items[2].dn == pytest.approx(0.01)
    shape = moving.changing_cell(8)
    axes = np.array([c.semi_axes_um for c in shape])
    assert np.allclose(axes[2], (10.0, 3.75, 3.5)) and np.allclose(axes[0, :2], (8.0, 5.0))
    assert len({c.center_um for c in shape}) == 1
    with pytest.raises(SsdpcError, match="amplitude"):
        moving.changing_cell(4, amplitude=0.8)
