"""The second front end: conventional DPC stacks (an LED array's half-disk patterns) through the same
phase methods. Checked on real images (a phase Siemens star, Waller-Lab/dpc-cMat) against the
Waller-Lab DPC solver's phase, and on stacks this package's multislice simulator makes of known beads."""

import math
from pathlib import Path

import numpy as np
import pytest
import tifffile

from napari_ssdpc.cli.main import main
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.led_dpc import reconstruct_dpc
from napari_ssdpc.settings.dpc_optics import DpcOptics
from napari_ssdpc.simulation.led_dpc import simulate_dpc_stack
from napari_ssdpc.simulation.phantoms import Sphere, Spheres

DATA = Path(__file__).parents[1] / "data" / "dpc_cmat"


@pytest.fixture(scope="module")
def star():
    """The real stack, its optics and the Waller-Lab solver's phase of it (tests/data/dpc_cmat/README.md)."""
    images = tifffile.imread(DATA / "testDataset_dpc.tif")
    return images, DpcOptics.from_yaml(DATA / "optics.yaml"), tifffile.imread(DATA / "peer_phase.tif")


def _corr(a, b) -> float:
    return float(np.corrcoef(np.ravel(a), np.ravel(b))[0, 1])


@pytest.mark.parametrize("method", ["tikhonov", "tv"])
def test_the_real_siemens_star_is_the_waller_lab_solvers_phase(star, method):
    images, optics, peer = star
    r = reconstruct_dpc(images, optics, method)
    assert r.phase.shape == peer.shape and r.delta_n is None
    assert r.pixel_um == pytest.approx(4.54 / 40)
    # measured: 0.99967 (tikhonov), 0.99966 (tv); the same sign, the same scale within 1 %
    assert _corr(r.phase, peer) >= 0.999
    assert np.std(r.phase) / np.std(peer) == pytest.approx(1.0, abs=0.03)


def test_patterns_turned_half_a_turn_give_the_opposite_phase(star):
    """The patterns' angles are read as documented: each lit half turned by 180° is the other half."""
    images, optics, peer = star
    turned = optics.replace(patterns_deg=[(a + 180) % 360 for a in optics.patterns_deg])
    assert _corr(reconstruct_dpc(images, turned, "tikhonov").phase, peer) <= -0.999


def _spheres(beads) -> Spheres:
    """Spheres of ((x, y, z) µm, diameter µm, RI)."""
    return Spheres([Sphere(c, d, n) for c, d, n in beads])


def _projected_phase(beads, optics, shape):
    """2π/λ ∫ Δn dz of spheres on the camera's pixel centres, rad."""
    ny, nx = shape
    x = (np.arange(nx) - (nx - 1) / 2) * optics.pixel_um
    y = (np.arange(ny) - (ny - 1) / 2) * optics.pixel_um
    xx, yy = np.meshgrid(x, y)
    out = np.zeros(shape)
    for (cx, cy, _), d, n in beads:
        chord = 2 * np.sqrt(np.clip((d / 2) ** 2 - (xx - cx) ** 2 - (yy - cy) ** 2, 0, None))
        out += 2 * math.pi / optics.wavelength_um * (n - optics.medium_index) * chord
    return out


def test_simulated_beads_in_2d_have_their_phase_where_they_are():
    optics = DpcOptics(
        wavelength_um=0.52, objective_na=0.4, magnification=20.0, camera_pixel_um=6.5, medium_index=1.33,
        illumination_na=0.4, patterns_deg=[0.0, 180.0, 90.0, 270.0],
    )  # fmt: skip
    beads = [((-3.0, 2.0, 0.0), 4.0, 1.35), ((4.0, -3.0, 0.0), 3.0, 1.36)]
    shape = (64, 64)
    stack = simulate_dpc_stack(_spheres(beads), optics, shape, source_spacing_na=0.03)
    truth = _projected_phase(beads, optics, shape)
    x = (np.arange(64) - 31.5) * optics.pixel_um
    # measured: tikhonov 0.85 and 0.87 of the true peak, tv 0.88 and 0.90 (the lowest frequencies, which
    # the halves hardly see, held back by α; the resolution)
    for method, tol in (("tikhonov", 0.2), ("tv", 0.12)):
        phase = reconstruct_dpc(stack, optics, method).phase
        for (cx, cy, _), _, _ in beads:
            i, j = np.argmin(abs(x - cy)), np.argmin(abs(x - cx))
            box = (slice(i - 3, i + 4), slice(j - 3, j + 4))
            k = np.unravel_index(np.argmax(phase[box]), (7, 7))
            assert max(abs(k[0] - 3), abs(k[1] - 3)) <= 1, (method, k)  # the peak within a pixel
            assert phase[box].max() == pytest.approx(truth[box].max(), rel=tol), method


def test_an_impossible_instrument_or_a_stack_that_does_not_fit_it_is_one_line(star, tmp_path):
    images, optics, _ = star
    with pytest.raises(SsdpcError, match="illumination_na 0.5 is above objective_na 0.4"):
        optics.replace(illumination_na=0.5)
    with pytest.raises(SsdpcError, match=r"the stack is \(3, 540, 960\), the optics describe 4 patterns"):
        reconstruct_dpc(images[:3], optics)
    with pytest.raises(SsdpcError, match="'multislice' method takes z-stacks"):
        reconstruct_dpc(images, optics, "multislice")
    with pytest.raises(SsdpcError, match="z range is for z-stacks"):
        reconstruct_dpc(images, optics, z_min_um=-2.0)
    with pytest.raises(SsdpcError, match="undersamples"):
        optics.replace(magnification=5.0)


def test_ssdpc_dpc_writes_the_phase_in_micrometres(star, tmp_path, capsys):
    out = tmp_path / "star.ome.tif"
    argv = ["dpc", DATA / "testDataset_dpc.tif", "--optics", DATA / "optics.yaml", "-o", out]
    assert main([str(a) for a in argv]) == 0
    assert "phase" in capsys.readouterr().out
    with tifffile.TiffFile(out) as tif:
        ome = tif.ome_metadata
        phase = tif.asarray()
    assert 'PhysicalSizeX="0.1135"' in ome and "PhysicalSizeXUnit" in ome
    assert "&quot;quantity&quot;: &quot;phase&quot;" in ome
    assert _corr(phase, star[2]) >= 0.999
    # the optics file of the other front end, a missing stack: one line each, nothing written
    lf_optics = tmp_path / "lf.yaml"
    lf_optics.write_text("objective: {na: 0.4}\nmla: {pitch_um: 500}\n")
    stack, optics = DATA / "testDataset_dpc.tif", DATA / "optics.yaml"
    for given, optics_file, out, words in (
        (stack, lf_optics, "a.ome.tif", "light-field optics"),
        (tmp_path / "none.tif", optics, "b.ome.tif", "not found"),
    ):
        assert main([str(a) for a in ("dpc", given, "--optics", optics_file, "-o", tmp_path / out)]) == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lf.yaml", "star.ome.tif"]


def _stack_optics():
    """40x / 0.65 in water, σ = 1, focal planes −4..4 µm every 1 µm (the kind of stack of Chen et al. 2016)."""
    return DpcOptics(
        wavelength_um=0.52, objective_na=0.65, magnification=40.0, camera_pixel_um=6.5, medium_index=1.33,
        illumination_na=0.65, patterns_deg=[0.0, 180.0, 90.0, 270.0], z_um=[float(z) for z in range(-4, 5)],
    )  # fmt: skip


def _beads_found(delta_n, z_um, optics, beads):
    """Per bead: its integrated Δn over its neighbourhood (1 µm around it laterally, ±2.5 µm) over the
    truth's, and the depth of the peak of Δn within 2 µm of it on its axis."""
    ny, nx = delta_n.shape[1:]
    x = (np.arange(nx) - (nx - 1) / 2) * optics.pixel_um
    y = (np.arange(ny) - (ny - 1) / 2) * optics.pixel_um
    xx, yy = np.meshgrid(x, y)
    dz = float(z_um[1] - z_um[0])
    out = []
    for (cx, cy, cz), d, n in beads:
        near = ((xx - cx) ** 2 + (yy - cy) ** 2) < (d / 2 + 1.0) ** 2
        mass = delta_n[abs(z_um - cz) <= 2.5][:, near].sum() * optics.pixel_um**2 * dz
        i, j = np.argmin(abs(y - cy)), np.argmin(abs(x - cx))
        axis = delta_n[:, i - 1 : i + 2, j - 1 : j + 2].mean(axis=(1, 2))
        window = np.flatnonzero(abs(z_um - cz) <= 2.0)
        k = window[np.argmax(axis[window])]
        out.append((mass / ((n - optics.medium_index) * math.pi / 6 * d**3), float(z_um[k]), float(axis[k]), axis))
    return out


def test_a_simulated_bead_in_a_z_stack_is_found_at_its_depth_with_its_mass():
    optics = _stack_optics()
    beads = [((0.5, -0.5, 2.0), 2.5, 1.345)]
    stack = simulate_dpc_stack(_spheres(beads), optics, (48, 48), source_spacing_na=0.05)
    assert stack.shape == (4, 9, 48, 48)
    r = reconstruct_dpc(stack, optics, "tv", z_min_um=-6.0, z_max_um=6.0, dz_um=0.5)
    assert r.phase is None and r.delta_n.shape == (25, 48, 48) and r.report["tv_sign"].startswith("auto: denser")
    ((mass, depth, peak, _),) = _beads_found(r.delta_n, r.z_um, optics, beads)
    assert depth == pytest.approx(2.0, abs=0.5)  # measured 2.0
    assert mass == pytest.approx(1.0, abs=0.1)  # measured 1.015
    # 'tikhonov' puts the bead near its depth too, but cannot give its mass: the halves' transfer
    # functions vanish at zero frequency, so a linear inverse sees no integral of Δn (measured 0.01)
    lin = reconstruct_dpc(stack, optics, "tikhonov", z_min_um=-6.0, z_max_um=6.0, dz_um=0.5)
    ((_, lin_depth, _, _),) = _beads_found(lin.delta_n, lin.z_um, optics, beads)
    assert lin_depth == pytest.approx(2.0, abs=1.0)  # measured 3.0


@pytest.mark.slow
def test_two_simulated_beads_on_one_axis_are_both_found_beside_a_third():
    optics = _stack_optics()
    beads = [((0.0, 0.0, -2.5), 2.5, 1.345), ((0.0, 0.0, 2.5), 2.5, 1.345), ((3.5, 2.5, 0.0), 3.0, 1.34)]
    stack = simulate_dpc_stack(_spheres(beads), optics, (80, 80), source_spacing_na=0.04)
    r = reconstruct_dpc(stack, optics, "tv", z_min_um=-6.0, z_max_um=6.0, dz_um=0.5)
    found = _beads_found(r.delta_n, r.z_um, optics, beads)
    # measured: masses 1.08, 1.09, 1.07; depths −3.0, +2.5, +0.5 µm; peaks 0.0094, 0.0106 (true 0.015)
    for (mass, depth, _, _), (centre, _, _) in zip(found, beads):
        assert mass == pytest.approx(1.0, abs=0.15)
        assert depth == pytest.approx(centre[2], abs=0.6)
    # the lower bead of the pair is not taken into the upper: Δn between them falls to 0.56 of the lower peak
    axis = found[0][3]
    between = axis[abs(r.z_um) <= 0.25].mean()
    assert between < 0.7 * min(found[0][2], found[1][2])


def test_the_transfer_functions_are_the_source_sums_of_the_weak_object_model():
    """H_phase of a defocused slab from LedPatterns (an FFT correlation) against the weak-object sum over
    the half-disk's source points written out (paper Eqs. 2-4), at a few frequencies: the same function."""
    from napari_ssdpc.physics.led_transfer import LedPatterns
    from napari_ssdpc.physics.pupil import eta

    optics = _stack_optics().replace(z_um=[-1.5, 2.0])
    shape = (96, 96)
    patterns = LedPatterns(optics, shape)
    _, hp = patterns.band([0.5])  # a slab at z = 0.5 µm: defocus 2.0 and −1.5 µm
    du = 1.0 / (96 * optics.pixel_um)
    # the source points of the 90° half on an 8x finer lattice, hard edges
    step = du / 8
    m = int(optics.source_radius / step) + 1
    wy, wx = np.mgrid[-m : m + 1, -m : m + 1] * step
    src = (np.hypot(wx, wy) <= optics.source_radius) & (wy > 0)
    wx, wy = wx[src], wy[src]

    def pupil(x, y):
        return (np.hypot(x, y) <= optics.cutoff).astype(float)

    def eta_of(x, y):
        return eta(x**2 + y**2, optics.medium_index, optics.wavelength_um).real

    def weak_object(ux, uy, d):
        """W(u) = Σ_w S P(w + u) P*(w) exp(i2πd[η(w + u) − η(w)]) / Σ_w S."""
        ph = np.exp(2j * np.pi * d * (eta_of(wx + ux, wy + uy) - eta_of(wx, wy)))
        return np.sum(pupil(wx + ux, wy + uy) * pupil(wx, wy) * ph) / len(wx)

    for iy, ix in ((0, 3), (2, 5), (-4, 1), (6, -2), (10, 3), (-12, -7)):
        for f, zf in enumerate(optics.z_um):
            d = 0.5 - zf
            u = (ix * du, iy * du)
            # H_phase(u) = i [W(u) − W*(−u)] / I0 (I0 = 1: the half lies inside the pupil); measured
            # within 0.015 of a peak |H| of 0.56 (the disks' one-sample edge ramps; 0.029 on a 48² grid)
            expected = 1j * (weak_object(*u, d) - np.conj(weak_object(-u[0], -u[1], d)))
            got = hp[0, 2 * len(optics.z_um) + f, iy, ix] / patterns.i0[0]
            assert got == pytest.approx(expected, abs=0.03), (iy, ix, zf)


@pytest.mark.slow
def test_a_strong_bead_in_a_z_stack_is_refined_by_multislice():
    """A 2.5 µm bead of Δn 0.05 (1.5 rad through it): the first-order 'tv' overestimates its mass; the
    multislice model of the half-disk images, from the 'tv' answer, brings it back."""
    optics = _stack_optics()
    beads = [((0.5, -0.5, 2.0), 2.5, 1.38)]
    stack = simulate_dpc_stack(_spheres(beads), optics, (48, 48), source_spacing_na=0.05)
    z = {"z_min_um": -3.0, "z_max_um": 6.0, "dz_um": 0.5}
    tv = reconstruct_dpc(stack, optics, "tv", **z)
    ms = reconstruct_dpc(stack, optics, "multislice", **z)
    ((tv_mass, _, _, _),) = _beads_found(tv.delta_n, tv.z_um, optics, beads)
    ((ms_mass, ms_depth, ms_peak, _),) = _beads_found(ms.delta_n, ms.z_um, optics, beads)
    # measured: tv 1.39, multislice 1.10 (30 iterations, 25 s); its depth 2.5 µm; the residual 34 -> 3.2 x the noise
    assert tv_mass > 1.25 and ms_mass == pytest.approx(1.0, abs=0.15)
    assert ms_depth == pytest.approx(2.0, abs=0.6) and ms_peak > 0.035
    assert ms.report["multislice_residual_over_noise"] < 0.2 * ms.report["multislice_starts_over_noise"]["tv"]


def test_three_patterns_written_as_one_rgb_page_are_three_images(star, tmp_path):
    """tifffile writes three images as one RGB page (planar or interleaved): the DPC reader takes each
    sample as an image, in order; a result of napari-ssdpc is refused."""
    from napari_ssdpc.io.frames import read_stack

    images = star[0][:3]
    tifffile.imwrite(tmp_path / "planar.tif", images)  # (3, y, x): one page of three samples
    tifffile.imwrite(tmp_path / "interleaved.tif", np.moveaxis(images, 0, -1), photometric="rgb")
    for name in ("planar.tif", "interleaved.tif"):
        np.testing.assert_array_equal(read_stack(tmp_path / name), images)
    out = tmp_path / "star.ome.tif"
    optics = DATA / "optics.yaml"
    assert main([str(a) for a in ("dpc", DATA / "testDataset_dpc.tif", "--optics", optics, "-o", out)]) == 0
    with pytest.raises(SsdpcError, match="a reconstruction result"):
        read_stack(out)
