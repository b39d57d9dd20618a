"""The multislice model of the views: its background, its gradient, its weak-object limit and its
agreement with the simulator on weak and strong beads (docs/nonlinear.md)."""

import math

import numpy as np
import pytest

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics import transfer
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.multislice_source import square_roi
from napari_ssdpc.physics.views_multislice import ViewsMultislice
from napari_ssdpc.reconstruction.forward import ViewModel
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.settings.lenslets import circle_overlap_fraction
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.phantoms import Sphere, pmma_bead


@pytest.fixture(scope="module")
def optics():
    return Optics.paper().replace(condenser_na=0.3)


def _grid(optics, n):
    return (np.arange(n) - (n - 1) / 2) * optics.object_pixel_um


def _lit(optics, n, min_light=0.05):
    """The lenslets with direct light at the optics' condenser NA (as ViewContrast keeps them)."""
    lenslets = nominal_lenslets(optics)
    _, _, i0 = transfer.lenslet_transfer_functions(optics, lenslets, (n, n), optics.object_pixel_um)
    return [ln for ln, i in zip(lenslets, i0) if i >= min_light * max(i0)]


def _first_order(optics, lenslets, n, z, dz, dn):
    """The contrast of the first-order model (paper Eqs. 2-4) of a Δn volume on the views' grid."""
    vm = ViewModel.for_lenslets(optics, lenslets, (n, n), optics.object_pixel_um, z)
    phi = (2 * math.pi * dz / optics.wavelength_um * dn).astype(np.float32)  # phase per slab, rad
    band = vm.take(vm.bk.rfft2(phi, norm="ortho"))
    return vm.images(vm.forward(band)) / vm.w[:, None, None]


def _rel(a, b):
    return float(np.sqrt(np.sum((a - b) ** 2) / np.sum(b**2)))


# ------------------------------------------------------------------------------ background
def test_without_sample_or_with_a_uniform_slab_every_view_is_one(optics):
    x = _grid(optics, 24)
    lenslets = _lit(optics, 24)
    model = ViewsMultislice(optics, lenslets, x, x, [-1.0, 0.0, 1.0], source_spacing_na=0.02)
    assert model.view_shape == (len(lenslets), 24, 24)
    np.testing.assert_allclose(model.views(np.zeros(model.shape)), 1.0, atol=2e-5)
    # a layer of constant Δn over the whole (periodic) field only delays the light: no contrast
    dn = np.zeros(model.shape)
    dn[1] = 0.05
    np.testing.assert_allclose(model.views(dn), 1.0, atol=2e-5)
    # a bead does make contrast
    bead = Sphere((0.0, 0.0, 0.0), 4.0, 1.528, medium_index=1.518)
    assert np.abs(model.views(bead.volume(model.z_um, model.y_um, model.x_um).real) - 1).max() > 0.05


def test_direct_light_is_the_overlap_of_source_disk_and_sub_aperture(optics):
    """I0_k ∝ area of the source disk inside A_k: exact for lenslets wholly inside the pupil, even
    with source points 0.03 NA apart (2 across a sub-aperture's radius), once the points are weighted
    per lenslet and sub-sampled at the apertures (docs/nonlinear.md)."""
    x = _grid(optics, 32)
    inside = [ln for ln in _lit(optics, 32) if ln.fraction == 1.0]
    rho, r_s = optics.subaperture_radius, optics.source_radius
    area = circle_overlap_fraction(np.hypot(*np.array([ln.u for ln in inside]).T), rho, r_s)
    assert area.min() < 0.8  # straddling lenslets are among them

    def worst(**kw):
        model = ViewsMultislice(optics, inside, x, x, [0.0], dz_um=1.0, source_spacing_na=0.03, **kw)
        return np.abs(model.i0 / model.i0.max() / (area / area.max()) - 1).max()

    assert worst() < 0.01  # measured 0.005
    assert worst(source_subsamples=1, edge_weights=False) > 0.05  # each point its own cell: 0.10


def test_inputs_are_checked(optics):
    x = _grid(optics, 24)
    lenslets = _lit(optics, 24)
    with pytest.raises(SsdpcError, match="square"):
        ViewsMultislice(optics, lenslets, x, x, [0.0], dz_um=1.0, roi=(slice(0, 20), slice(0, 16)))
    with pytest.raises(SsdpcError, match="evenly"):
        ViewsMultislice(optics, lenslets, x, x, [0.0, 1.0, 3.0])
    model = ViewsMultislice(optics, lenslets, x, x, [0.0, 1.0], source_spacing_na=0.04)
    with pytest.raises(SsdpcError, match="shape"):
        model.views(np.zeros((3, 24, 24)))
    need = model.bytes_needed
    assert model.n_sources * model.n_subsources * len(lenslets) * model.m**2 * 8 < need
    with pytest.raises(SsdpcError, match=r"region with 2 planes needs about .* GiB but .* are free: choose a smaller"):
        ViewsMultislice(optics, lenslets, x, x, [0.0, 1.0], source_spacing_na=0.04, max_bytes=need - 1)
    rows, cols = square_roi(x, x, (5.0, -3.0), 10.0)
    assert rows.stop - rows.start == cols.stop - cols.start >= 10.0 / optics.object_pixel_um
    assert abs(np.mean(x[cols]) - 5.0) < optics.object_pixel_um and abs(np.mean(x[rows]) + 3.0) < optics.object_pixel_um


@pytest.mark.parametrize("substeps", [1, 2])
def test_empty_planes_are_one_propagation_step_with_the_same_views(optics, substeps):
    """Planes of Δn 0 before, between and after the objects: the forward pass merges their slabs into
    one step (and skips those before the first object); the views are those of every slab."""
    x = _grid(optics, 20)
    lenslets = _lit(optics, 20)[::2]
    z = np.arange(-6.0, 6.01, 1.0)
    model = ViewsMultislice(optics, lenslets, x, x, z, substeps=substeps, source_spacing_na=0.08, dtype=np.complex128)
    dn = np.zeros(model.shape)
    dn[3] = Sphere((1.0, 0.0, 0.0), 3.0, 1.60, medium_index=1.518).volume([0.0], model.y_um, model.x_um).real[0]
    dn[8] = -0.5 * dn[3].T
    merged = model.views(dn)
    screens = model._screens(dn)
    every = sum(
        np.einsum("jqk,jqkyx->kyx", model._wgt[sl], np.abs(model._propagate_chunk(screens, sl, False)[0]) ** 2)
        for sl in model._chunks()
    )
    np.testing.assert_allclose(merged, model._interpolate(every) / model._i0, rtol=1e-9, atol=1e-9)
    assert np.abs(merged - 1).max() > 0.05  # the objects do make contrast


# -------------------------------------------------------------------------------- gradient
@pytest.mark.parametrize("refine, substeps", [(1, 1), (2, 2)])
def test_gradient_matches_finite_differences(optics, refine, substeps):
    x = _grid(optics, 16)
    lenslets = [ln for ln in _lit(optics, 16)][::3]
    model = ViewsMultislice(
        optics,
        lenslets,
        x,
        x,
        [-2.0, 0.0, 2.0],
        refine=refine,
        substeps=substeps,
        source_spacing_na=0.1,
        chunk=7,
        dtype=np.complex128,
    )
    rng = np.random.default_rng(3)
    dn = 0.03 * rng.standard_normal(model.shape)
    data = 1 + 0.1 * rng.standard_normal(model.view_shape)
    weight = rng.uniform(0.5, 1.5, model.view_shape)
    value, grad = model.misfit(dn, data, weight)
    assert value == pytest.approx(0.5 * np.sum(weight * (model.views(dn) - data) ** 2), rel=1e-12)
    eps = 1e-6
    for _ in range(3):
        d = rng.standard_normal(model.shape)
        fd = (model.misfit(dn + eps * d, data, weight)[0] - model.misfit(dn - eps * d, data, weight)[0]) / (2 * eps)
        assert np.sum(grad * d) == pytest.approx(fd, rel=1e-3)
    model.memory_mb = 0.0  # the backward pass recomputes the fields: the same gradient
    np.testing.assert_allclose(model.misfit(dn, data, weight)[1], grad, rtol=1e-10, atol=1e-12 * np.abs(grad).max())


def test_the_model_runs_on_a_device_backend_with_the_same_numbers(optics):
    """Every array and FFT of the model and its gradient goes through its backend: on a device
    that refuses host arrays (CuPy's rules, NumPy's numbers) the views and the gradient are the CPU's."""
    from fake_device import fake_gpu

    x = _grid(optics, 16)
    lenslets = _lit(optics, 16)[::3]
    kw = dict(source_spacing_na=0.1, chunk=5)
    cpu_model = ViewsMultislice(optics, lenslets, x, x, [-2.0, 0.0, 2.0], **kw)
    bk = fake_gpu()
    dev_model = ViewsMultislice(optics, lenslets, x, x, [-2.0, 0.0, 2.0], backend=bk, **kw)
    rng = np.random.default_rng(5)
    dn = (0.03 * rng.standard_normal(cpu_model.shape)).astype(np.float32)
    data = (1 + 0.1 * rng.standard_normal(cpu_model.view_shape)).astype(np.float32)
    np.testing.assert_allclose(dev_model.i0, cpu_model.i0, rtol=1e-6)
    np.testing.assert_allclose(bk.to_host(dev_model.views(bk.asarray(dn))), cpu_model.views(dn), rtol=1e-5, atol=1e-6)
    v_cpu, g_cpu = cpu_model.misfit(dn, data)
    v_dev, g_dev = dev_model.misfit(bk.asarray(dn), bk.asarray(data))
    assert v_dev == pytest.approx(v_cpu, rel=1e-5)
    np.testing.assert_allclose(bk.to_host(g_dev), g_cpu, rtol=1e-4, atol=1e-5 * np.abs(g_cpu).max())
    assert g_cpu.dtype == np.float32  # complex64 fields give float32 gradients


# ------------------------------------------------------------------------- weak-object limit
#: An imperfect instrument: the objective's astigmatism, coma and spherical aberration (Noll 5, 7,
#: 11, waves rms), one lenslet defocused by 0.5 waves at its edge, one with its sub-aperture 5 µm off
#: in the MLA plane and 3 % wider, the condenser 0.01 NA off axis.
ABERRATIONS = Aberrations(
    objective_zernike_waves=(0, 0, 0, 0, 0.15, 0, 0.2, 0, 0, 0, 0.4),
    lenslets=(
        LensletTerms(row=-1, col=-1, defocus_waves=0.5),
        LensletTerms(row=0, col=0, offset_um=(5.0, -3.0), radius_scale=1.03),
    ),
    condenser_offset_na=(0.01, 0.0),
)


@pytest.mark.parametrize("instrument", ["nominal", "aberrated"])
def test_weak_object_limit_is_the_first_order_model(optics, instrument):
    """A bead of Δn 5e-4 (0.04 rad) 6 µm behind the focal plane: the multislice views' contrast is
    the first-order model's (independent code, the WOTFs of physics.transfer), parallax included;
    with the instrument's aberrations too (both sample the one Pupil, each in its own way)."""
    if instrument == "aberrated":
        optics = optics.replace(aberrations=ABERRATIONS)
    n, dz = 48, 1.0
    x = _grid(optics, n)
    lenslets = _lit(optics, n)
    z = 6.0 + dz * np.arange(-3, 4)
    model = ViewsMultislice(optics, lenslets, x, x, z, source_spacing_na=0.03, pixel_integration=False)
    bead = Sphere((1.0, -2.0, 6.0), 6.0, 1.518 + 5e-4, medium_index=1.518)
    dn = bead.volume(z, model.y_um, model.x_um).real
    contrast = model.views(dn) - 1
    linear = _first_order(optics, lenslets, n, z, dz, dn)
    assert np.sqrt(np.mean(linear**2)) > 1e-3
    assert _rel(contrast, linear) < 0.1  # measured 0.06 (0.04 at 0.02 NA); aberrated 0.081
    if instrument == "aberrated":  # the aberrations change the views: the agreement is not the nominal one's
        nominal = _first_order(Optics.paper().replace(condenser_na=0.3), lenslets, n, z, dz, dn)
        assert _rel(contrast, nominal) > 0.5  # measured 1.05
    # the same bead in front of the focal plane looks different: the depth is seen
    mirrored = _first_order(optics, lenslets, n, -z[::-1], dz, dn[::-1])
    assert _rel(contrast, mirrored) > 0.5


# ------------------------------------------------------------------------ against the simulator
def _simulated_views(phantom, optics):
    """Noise-free frame, flat and white of the simulator; views calibrated on the white frame and
    flat-fielded (the pipeline's path)."""
    from napari_ssdpc.calibration import calibrate
    from napari_ssdpc.physics.lattice import Grid
    from napari_ssdpc.reconstruction.contrast import ViewContrast
    from napari_ssdpc.simulation.camera import Camera
    from napari_ssdpc.simulation.multislice import Source
    from napari_ssdpc.simulation.phantoms import optics_for
    from napari_ssdpc.simulation.sample_free import flat_frame, white_frame
    from napari_ssdpc.simulation.simulate import simulate

    optics = optics_for(phantom, optics)
    grid, camera, source = Grid.nominal(optics), Camera(noise=False), Source(step=4)
    frame = simulate(phantom, optics, grid=grid, camera=camera, source=source).frame
    flat = flat_frame(optics, grid=grid, camera=camera, source=source)
    contrast = ViewContrast(optics, calibrate(white_frame(optics, grid=grid, camera=camera), optics), flat=flat)
    return optics, contrast, contrast(frame)


@pytest.mark.slow
@pytest.mark.parametrize(
    "phantom, dz, refine, ms_max, fo_min",
    [
        # measured (docs/nonlinear.md): multislice 0.071 / first order 0.234
        (Sphere((0.0, 0.0, 5.0), 6.0, 1.528, medium_index=1.518), 1.0, 1, 0.1, 0.15),  # 0.72 rad
        (pmma_bead(), 1.0, 1, 0.1, 0.5),  # 4.4 rad: 0.077 / 0.740
        (Sphere((0.0, 0.0, 0.0), 5.0, 1.46, medium_index=1.33), 0.5, 2, 0.1, 1.0),  # silica, 7.9 rad: 0.099 / 3.03
    ],
    ids=["weak", "pmma", "silica"],
)
def test_views_match_the_simulator(optics, phantom, dz, refine, ms_max, fo_min):
    _views_match_the_simulator(optics, phantom, dz, refine, ms_max, fo_min)


@pytest.mark.slow
def test_views_match_the_simulator_with_aberrations(optics):
    """The simulator's aberrated pupil (its own sampling of it) and the model's agree as the ideal ones
    do. Every lenslet keeps its nominal radius here: the calibration's axis fit reads the white
    frame's brightness with the nominal sub-apertures, and a lenslet 3 % wider (6 % more light) is
    refused there (rms 1.1 %)."""
    same_radius = tuple(t.model_copy(update={"radius_scale": 1.0}) for t in ABERRATIONS.lenslets)
    aberrations = ABERRATIONS.model_copy(update={"lenslets": same_radius})
    weak = Sphere((0.0, 0.0, 5.0), 6.0, 1.528, medium_index=1.518)
    _views_match_the_simulator(optics.replace(aberrations=aberrations.to_dict()), weak, 1.0, 1, 0.1, 0.15)


def _views_match_the_simulator(optics, phantom, dz, refine, ms_max, fo_min):
    optics, contrast, views = _simulated_views(phantom, optics)
    x, y = contrast.x_um, contrast.y_um
    r = phantom.diameter_um / 2
    nz = int(math.ceil(2 * r / dz)) + 1
    z = phantom.center_um[2] + dz * (np.arange(nz) - (nz - 1) / 2)
    roi = square_roi(x, y, phantom.center_um[:2], 2 * r + 20.0)
    model = ViewsMultislice(optics, contrast.lenslets, x, y, z, roi=roi, refine=refine, source_spacing_na=0.03)
    dn = phantom.volume(z, model.y_um, model.x_um, optics.medium_index).real
    data, mask = model.crop(views), model.crop(contrast.view_mask)
    signal = np.where(mask, data - 1, 0)
    err_ms = _rel(np.where(mask, model.views(dn) - 1, 0), signal)
    vm = ViewModel.for_lenslets(
        optics, contrast.lenslets, contrast.mask.shape, contrast.pixel_um, z, i0=contrast.level[contrast.lit]
    )
    phi = np.stack(
        [phantom.slab(zi - dz / 2, zi + dz / 2, y, x, contrast.pixel_um, optics.medium_index).real for zi in z]
    )
    band = vm.take(vm.bk.rfft2((2 * math.pi / optics.wavelength_um * phi).astype(np.float32), norm="ortho"))
    linear = model.crop(vm.images(vm.forward(band)) / vm.w[:, None, None])
    err_fo = _rel(np.where(mask, linear, 0), signal)
    print(f"relative error of the views: multislice {err_ms:.3f}, first order {err_fo:.3f}")
    assert err_ms < ms_max
    assert err_fo > fo_min
    if fo_min >= 0.5:  # strong objects: the multislice model must beat the first-order one by far
        assert err_ms < 0.3 * err_fo


def test_every_model_samples_the_one_pupil(optics):
    """The transfer functions' soft-edged sub-aperture, the simulator's cell fractions and the
    multislice model's hard edges are samplings of one Pupil: they agree on its area."""
    from napari_ssdpc.physics.apertures import subaperture_windows
    from napari_ssdpc.physics.pupil import Pupil, subaperture_pupil

    pupil = Pupil.of(optics)
    edge = [ln for ln in nominal_lenslets(optics) if 0.3 < ln.fraction < 0.9][0]  # cut by the objective's edge
    du = pupil.rho / 40
    soft, _, _ = subaperture_pupil(optics, edge.u, (128, 128), du)
    _, cells = subaperture_windows([edge.u], pupil, du, 128)
    t = (np.arange(128 * 4) - 256 + 0.5) * du / 4
    hard = pupil.subaperture(edge.u[0] + t[None, :], edge.u[1] + t[:, None], edge.u)
    areas = [soft.sum() * du**2, (cells[0] ** 2).sum() * du**2, hard.sum() * (du / 4) ** 2]
    full = math.pi * pupil.rho**2
    assert 0.3 * full < areas[0] < 0.9 * full
    np.testing.assert_allclose(areas, areas[0], rtol=2e-3)
