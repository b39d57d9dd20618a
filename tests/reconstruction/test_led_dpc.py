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
    stack = simulate_dpc_stack(Spheres([Sphere(c, d, n) for c, d, n in beads]), optics, shape, source_spacing_na=0.03)
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
    with pytest.raises(SsdpcError, match="'multislice' method does not take DPC stacks"):
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
