"""The pupil fitted to beads (reconstruction/pupil_fit.py): the objective's terms and every view's defocus
with the bead's sphere free, on views the same (small) multislice model made with a known pupil."""

import numpy as np
import pytest

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.transfer import lenslet_transfer_functions
from napari_ssdpc.physics.views_multislice import ViewsMultislice
from napari_ssdpc.reconstruction.bead_search import FINE_DZ_UM
from napari_ssdpc.reconstruction.beads_and_pupil import BeadsAndPupil
from napari_ssdpc.reconstruction.pupil_fit import PupilFit, check_pupil_fit
from napari_ssdpc.reconstruction.sphere_volume import spheres_volume
from napari_ssdpc.settings.aberrations import Aberrations
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import MultisliceSettings

N = 36  # view pixels per side
NOISE = 0.003
BEAD = np.array([[0.8, -0.5, 4.0, 2.5, 0.03]])  # x, y, z, R µm; Δn
TRUTH = {"c5": 0.06, "c11": 0.15, "d": 0.3}


class SmallViews:
    """A front end with a coarse model (source points every 0.1 NA, no refinement): its views, mask, lenslets."""

    def __init__(self, optics, lenslets):
        self.optics, self.lenslets = optics, lenslets
        self.x_um = self.y_um = (np.arange(N) - (N - 1) / 2) * optics.object_pixel_um
        self.view_mask = np.ones((len(lenslets), N, N), bool)

    def multislice_model(self, z_um, dz_um, roi, settings, *, backend=None, max_bytes=None):
        return ViewsMultislice(
            self.optics, self.lenslets, self.x_um, self.y_um, z_um, roi=roi, dz_um=dz_um, source_spacing_na=0.1,
            source_subsamples=1, backend=backend,
        )  # fmt: skip


@pytest.fixture(scope="module")
def bead_views():
    """The views of one bead (Δn 0.03, 5 µm) through a pupil with astigmatism, spherical aberration and
    every view defocused, with noise; the front end; the lenslets' keys."""
    optics = Optics.paper().replace(medium_index=1.33, condenser_na=0.3)
    every = nominal_lenslets(optics)
    _, _, i0 = lenslet_transfer_functions(optics, every, (16, 16), optics.object_pixel_um)
    lenslets = [ln for ln, i in zip(every, i0) if i >= 0.05 * max(i0)][::2]
    front = SmallViews(optics, lenslets)
    z = np.arange(-2.0, 10.0 + FINE_DZ_UM / 2, FINE_DZ_UM)
    model = front.multislice_model(z, FINE_DZ_UM, None, None)
    model.set_pupil_phase((0,) * 4 + (TRUTH["c5"],) + (0,) * 5 + (TRUTH["c11"],), np.full(len(lenslets), TRUTH["d"]))
    clean = model.views(spheres_volume(BEAD, z, model.y_um, model.x_um, FINE_DZ_UM))
    views = clean + NOISE * np.random.default_rng(5).standard_normal(clean.shape)
    return front, views


def test_the_pupil_and_the_bead_are_fitted_together(bead_views):
    front, views = bead_views
    start = BEAD.copy()
    start[0, 2] += 1.5  # the bead's depth and size as a wrong pupil leaves them
    start[0, 3] *= 1.2
    start[0, 4] = 0.02
    k = len(front.lenslets)
    job = BeadsAndPupil(front, views, start, MultisliceSettings(), noll=(5, 6, 11), defocus0=np.full(k, 0.25))
    fitted = job.fit(job.pack(start, np.zeros(3)))  # d0 = |d| from the rims, c from zero
    assert fitted.converged
    spheres, zernike, defocus = job.unpack(fitted.q)
    sigma = job.sigmas(fitted, NOISE)
    sz, sd = sigma[5:8], sigma[8]
    assert zernike == pytest.approx([TRUTH["c5"], 0.0, TRUTH["c11"]], abs=0.01)
    assert defocus == pytest.approx(np.full(k, TRUTH["d"]), abs=0.02)
    assert spheres[0] == pytest.approx(BEAD[0], abs=0.05)
    assert spheres[0, 4] == pytest.approx(BEAD[0, 4], abs=5e-4)
    # the uncertainties are those of the noise: the errors within 4 sigma, every term determined
    assert np.all(np.abs(zernike - [TRUTH["c5"], 0.0, TRUTH["c11"]]) < 4 * sz)
    assert np.all(np.abs(defocus - TRUTH["d"]) < 4 * sd)
    assert np.all(sz < 0.05) and sd < 0.05
    # the residual reaches the noise
    assert job.residual_over_noise(fitted.cost, NOISE) == pytest.approx(1.0, abs=0.1)


def test_the_sign_of_the_defocus_is_the_beads(bead_views):
    """The rims give |d| alone: started at either sign (Δn known), the fit ends at the beads' sign."""
    front, views = bead_views
    k = len(front.lenslets)
    for sign in (1, -1):
        job = BeadsAndPupil(front, views, BEAD, MultisliceSettings(), noll=(5, 11), defocus0=np.full(k, 0.25 * sign))
        fitted = job.fit(job.pack(BEAD, [0.0, 0.0]), fixed_dn=0.03)
        assert job.unpack(fitted.q)[2] == pytest.approx(np.full(k, TRUTH["d"]), abs=0.02)
        assert job.residual_over_noise(fitted.cost, NOISE) < 1.1


def _fit(sigma=0.01, converged=True, explained=True, medium_index=None, outside=False) -> PupilFit:
    from napari_ssdpc.reconstruction.bead import Bead

    residual = None if outside else 30.0 if not explained else 1.0
    bead = Bead((0.0, 0.0, 4.0), 5.0, 1.36, 0.03, residual, 1.5, True, explained and not outside)
    keys = ((0, 0), (0, 1))
    return PupilFit(
        (5, 11), np.array([0.05, 0.2]), np.array([0.01, sigma]), keys, np.array([0.3, 0.31]), np.array([0.01, 0.01]),
        (bead,), 12.0, 1.1, converged, medium_index,
    )  # fmt: skip


def test_the_fitted_terms_go_into_the_optics_and_the_report():
    fit = _fit()
    ab = fit.aberrations(Aberrations(objective_zernike_waves=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.1)))
    assert ab.objective_zernike_waves[4] == 0.05 and ab.objective_zernike_waves[10] == 0.2
    assert ab.objective_zernike_waves[6] == 0.1  # a term not fitted is kept
    assert [t.defocus_waves for t in ab.lenslets] == [0.3, 0.31]
    text = "\n".join(fit.report())
    assert "Z11 +0.200 ± 0.010" in text and "12.0 -> 1.1 x the noise" in text
    check_pupil_fit(fit, None)


@pytest.mark.parametrize(
    "fit, words",
    [
        (_fit(sigma=0.2), "does not determine Z11"),
        (_fit(converged=False), "did not converge"),
        (_fit(explained=False), "beads of another index than --bead-ri 1.36"),
        (_fit(outside=True), r"moved a bead out of the views of its region \(to \(0\.0, 0\.0, 4\.0\) µm\)"),
    ],
)
def test_a_fit_that_cannot_be_trusted_is_refused_in_one_line(fit, words):
    with pytest.raises(SsdpcError, match=words) as err:
        check_pupil_fit(fit, 1.36)
    assert "\n" not in str(err.value) and "nothing written" in str(err.value)


def test_a_pupil_fitted_to_beads_holds_for_samples_in_their_medium(monkeypatch):
    """The fitted calibration takes the beads' medium (a spherical aberration changes with it), and
    optics of another medium are refused in one line that names the fit in theirs."""
    from napari_ssdpc.calibration import calibrate
    from napari_ssdpc.physics.lattice import Grid
    from napari_ssdpc.reconstruction import optics_fit
    from napari_ssdpc.reconstruction.checks import check_optics_match
    from napari_ssdpc.settings.config import RunConfig
    from napari_ssdpc.simulation.sample_free import flat_frame, white_frame

    oil = Optics.paper().replace(condenser_na=0.25)
    grid = Grid.nominal(oil, axis_offset_px=(2.3, -1.4))
    cal = calibrate(white_frame(oil, grid=grid, rng=1), oil)
    monkeypatch.setattr(optics_fit, "fit_pupil", lambda *a, **k: _fit(medium_index=1.33))
    water = RunConfig.of(oil.replace(medium_index=1.33))
    fitted = optics_fit.fit_optics(cal, flat_frame(oil, grid=grid, rng=2), beads=optics_fit.BeadFrame(water, None))
    assert fitted.calibration.optics.medium_index == 1.33
    assert fitted.calibration.optics_fit["pupil"]["medium_index"] == 1.33
    assert "beads in a medium of 1.330" in "\n".join(fitted.report())
    check_optics_match(water.optics, fitted.calibration)
    with pytest.raises(SsdpcError, match=r"fitted to beads in 1\.33 .*--medium-index 1\.518 ") as err:
        check_optics_match(oil, fitted.calibration)
    assert "\n" not in str(err.value)


def test_beads_found_under_a_pupil_far_off_are_searched_again_under_the_one_reached(monkeypatch):
    """A joint fit that ends without converging (its beads found a wave of phase off under a pupil far
    from the instrument's) is started again from the pupil it reached, the beads searched under that
    pupil; a fit that converges there is the answer (the search and fits themselves are stand-ins)."""
    from types import SimpleNamespace

    from napari_ssdpc.calibration import calibrate
    from napari_ssdpc.physics.lattice import Grid
    from napari_ssdpc.reconstruction import beads as beads_module
    from napari_ssdpc.reconstruction import pupil_fit, reconstructor
    from napari_ssdpc.reconstruction.bead import Bead
    from napari_ssdpc.reconstruction.beads_and_pupil import Fitted
    from napari_ssdpc.settings.config import RunConfig
    from napari_ssdpc.simulation.sample_free import white_frame

    optics = Optics.paper().replace(condenser_na=0.25)
    cal = calibrate(white_frame(optics, grid=Grid.nominal(optics), rng=1), optics)
    searched_under, fits = [], []

    class Rec:  # the views and the optics of a start pupil
        def __init__(self, config, start, flat):
            self.optics, self.backend, self.z_um = start.optics, None, np.zeros(1)
            self.views = SimpleNamespace(lenslets=start.lenslets, measure=lambda frame, name: (None, None))

    def fit_beads(measurements, views, dn, z_um, optics, **_):
        searched_under.append((*optics.aberrations.objective_zernike_waves, *[0.0] * 11)[10])
        return [Bead((0.0, 0.0, 0.0), 5.0, 1.36, 0.03, 1.0, 1.5, True, True)]

    class Job:  # ends 0.43 waves along on its first fit, unconverged; converges from there
        def __init__(self, measurements, views, spheres, settings, noll, base_z, d0, backend):
            self.d0, self.spheres = np.asarray(d0), spheres

        def pack(self, spheres, zernike):
            return np.concatenate([np.ravel(spheres), zernike, [0.0]])

        def unpack(self, q):
            return q[:5].reshape(1, 5), q[5:-1], self.d0 + q[-1]

        def fit(self, q0, hold_pupil=False, **_):
            q = q0.copy()
            if not hold_pupil:
                q[-2] = 0.43 if not fits else 0.447
                fits.append(q0[-2])
            return Fitted(q, 1.0, hold_pupil or len(fits) > 1, np.eye(len(q)), list(range(len(q))))

        def beads(self, q, converged, *_):
            return [Bead((0.0, 0.0, 0.0), 5.0, 1.36, 0.03, 1.0, 1.5, converged, True)]

        def sigmas(self, fitted, noise):
            return np.full(len(fitted.q), 0.001)

        def residual_over_noise(self, cost, noise):
            return cost

    monkeypatch.setattr(reconstructor, "Reconstructor", Rec)
    monkeypatch.setattr(beads_module, "first_answer", lambda rec, views, **_: (None, 0.01))
    monkeypatch.setattr(beads_module, "fit_beads", fit_beads)
    monkeypatch.setattr(pupil_fit, "BeadsAndPupil", Job)
    fit = pupil_fit.fit_pupil(RunConfig.of(optics), cal, None, None)
    assert searched_under == [0.0, 0.43]  # the beads searched again under the pupil the first fit reached
    assert fits == [0.0, 0.43]  # and the second fit started there
    assert fit.converged and fit.zernike_waves[-1] == 0.447
