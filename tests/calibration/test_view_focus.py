"""Each view's focus measured on the white frame's EI rims (docs/aberrations.md), on the simulator's
white frames of instruments whose lenslets are out of focus."""

import dataclasses

import numpy as np
import pytest

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.calibration.view_focus import BLURRED_WAVES, fit_view_focus, rims_unmodelled
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.sample_free import white_frame

OPTICS = Optics.paper()
GRID = Grid.nominal(OPTICS, axis_offset_px=(2.3, -1.4), rotation_deg=0.3)


@pytest.fixture(scope="module")
def cal():
    return calibrate(white_frame(OPTICS, grid=GRID, rng=1), OPTICS)


def _terms(defocus: dict):
    return tuple(LensletTerms(row=r, col=c, defocus_waves=float(d)) for (r, c), d in defocus.items())


def _white(defocus: dict):
    return white_frame(OPTICS.replace(aberrations=Aberrations(lenslets=_terms(defocus))), grid=GRID, rng=2)


def test_an_instrument_in_focus_reads_in_focus(cal):
    fit = fit_view_focus(white_frame(OPTICS, grid=GRID, rng=2), cal, OPTICS)
    assert len(fit.keys) == 16  # every lenslet wholly inside the pupil
    assert np.all(fit.defocus_waves < 0.1)  # measured 0.066-0.070: the model's floor near focus
    assert not fit.blurred


def test_each_views_defocus_is_measured(cal):
    """Views defocused by 0.3-1.0 waves each (a lenslet array whose focal lengths differ): within
    0.05 waves (measured up to 0.035); the misfit falls."""
    keys = [(ln.row, ln.col) for ln in nominal_lenslets(OPTICS)]
    truth = dict(zip(keys, np.random.default_rng(3).uniform(0.3, 1.0, len(keys))))
    fit = fit_view_focus(_white(truth), cal, OPTICS)
    expected = np.array([truth[k] for k in fit.keys])
    assert np.abs(fit.defocus_waves - expected).max() < 0.05
    assert fit.misfit_after < 0.8 * fit.misfit_before
    assert fit.blurred and "refocus the camera" in fit.notice()
    # written as lenslet terms (the size: the rim cannot tell the sign)
    ab = fit.aberrations(Aberrations())
    assert ab.lenslet(*fit.keys[0]).defocus_waves == pytest.approx(fit.defocus_waves[0], abs=1e-4)


def test_the_sensor_off_focus_is_noticed(cal):
    """Every view 0.5 waves out of focus (the camera 2 mm off the lenslets' focal plane)."""
    fit = fit_view_focus(_white({(ln.row, ln.col): 0.5 for ln in nominal_lenslets(OPTICS)}), cal, OPTICS)
    assert np.median(fit.defocus_waves) == pytest.approx(0.5, abs=0.05)  # measured 0.484
    assert fit.blurred and np.median(fit.defocus_waves) > BLURRED_WAVES


def test_rims_that_cannot_be_measured_are_refused(cal):
    white = white_frame(OPTICS, grid=GRID, rng=2)
    overlapping = dataclasses.replace(cal, ei_radius_px=1.4 * cal.ei_radius_px)  # every rim inside a neighbour
    with pytest.raises(SsdpcError, match="rim free of its neighbours' light"):
        fit_view_focus(white, overlapping, OPTICS)
    with pytest.raises(SsdpcError, match="shape"):
        fit_view_focus(np.zeros((10, 10)), cal, OPTICS)


def test_the_calibration_says_when_the_views_are_out_of_focus(cal):
    """`calibrate` looks at two views' rims on every white frame (0.2-wave steps): in focus it reads
    under the threshold (measured 0.09) and says nothing; with every view 0.5 waves out of focus it
    reads 0.47, says so naming `ssdpc fit-optics`, and keeps the number in the JSON. Optics that give
    the lenslets their defocus (a fitted calibration) are not told again."""
    assert cal.rim_defocus_waves is not None and cal.rim_defocus_waves < BLURRED_WAVES
    off = {(ln.row, ln.col): 0.5 for ln in nominal_lenslets(OPTICS)}
    with pytest.warns(SsdpcWarning, match=r"rims are blurred .* 0\.4\d waves.*ssdpc fit-optics"):
        blurred = calibrate(_white(off), OPTICS)
    assert blurred.rim_defocus_waves == pytest.approx(0.5, abs=0.06)
    assert Calibration.from_dict(blurred.to_dict()).rim_defocus_waves == blurred.rim_defocus_waves
    modelled = OPTICS.replace(aberrations=Aberrations(lenslets=_terms(off)))
    assert rims_unmodelled(blurred.rim_defocus_waves, OPTICS) and not rims_unmodelled(0.47, modelled)
    old = dataclasses.replace(cal, rim_defocus_waves=None)
    assert "rim_defocus_waves" not in old.to_dict()  # a calibration without rims keeps its form
