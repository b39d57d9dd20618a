"""The pupil fitted to a frame of beads of an aberrated instrument (slow; docs/aberrations.md): spherical
aberration c₁₁ 0.224 waves rms and every view defocused by 0.5 waves, two 6 µm beads in water, the
nominal optics given; the issue's targets: the terms within 0.05 waves, the beads where they are."""

import numpy as np
import pytest

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.reconstruction.optics_fit import BeadFrame, fit_optics
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val

pytestmark = pytest.mark.slow

MEDIUM = 1.33
SPHERICAL, DEFOCUS = 0.224, 0.5
BEADS = (ph.Sphere((-20.0, 5.0, -10.0), 6.0, MEDIUM + 0.03), ph.Sphere((20.0, -5.0, 15.0), 6.0, MEDIUM + 0.03))


@pytest.fixture(scope="module")
def fitted(cache):
    nominal = val.paper_optics(0.25).replace(medium_index=MEDIUM)
    lenslets = Grid.nominal(nominal).lenslets(nominal)
    terms = tuple(LensletTerms(row=ln.row, col=ln.col, defocus_waves=DEFOCUS) for ln in lenslets)
    truth = nominal.replace(aberrations=Aberrations(objective_zernike_waves=(0.0,) * 10 + (SPHERICAL,), lenslets=terms))
    case = val.simulate_case("pf-two", ph.Spheres(BEADS, medium_index=MEDIUM), truth, cache_dir=cache, source_step=4)
    cal = calibrate(case.white, nominal)
    config = val.run_config(nominal, z=(-30.0, 30.0), dz=1.0)
    fit = fit_optics(cal, case.flat, nominal, case.white, beads=BeadFrame(config, case.frame, None, "pf-two"))
    return fit, case, cal, config


def test_the_objectives_terms_and_the_views_defocus_within_0_05_waves(fitted):
    pupil = fitted[0].pupil
    terms = dict(zip(pupil.noll, pupil.zernike_waves))
    assert terms[11] == pytest.approx(SPHERICAL, abs=0.05)
    assert max(abs(c) for j, c in terms.items() if j != 11) < 0.05
    assert np.abs(pupil.defocus_waves - DEFOCUS).max() < 0.05  # the sign from the beads, |d| from the rims
    assert pupil.residual_after < pupil.residual_before


def test_the_beads_are_where_they_are(fitted):
    beads = sorted(fitted[0].pupil.beads, key=lambda b: b.centre_um[0])
    assert len(beads) == 2
    for bead, truth in zip(beads, BEADS):
        assert np.allclose(bead.centre_um, truth.center_um, atol=0.5)
        assert bead.diameter_um == pytest.approx(truth.diameter_um, rel=0.05)
        assert bead.delta_n == pytest.approx(0.03, abs=0.003)


def test_the_fitted_pupil_is_written_and_used(fitted):
    fit = fitted[0]
    ab = fit.calibration.optics.aberrations
    assert ab.objective_zernike_waves[10] == pytest.approx(fit.pupil.zernike_waves[-1], abs=1e-4)
    assert "pupil" in fit.calibration.optics_fit
