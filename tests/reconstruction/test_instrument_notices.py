"""Signs on the white and flat frames of an instrument unlike its optics are said on every frame and
name `ssdpc fit-optics` (docs/aberrations.md)."""

import dataclasses
import warnings

import numpy as np
import pytest

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.errors import SsdpcWarning
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.reconstruction.contrast import ViewContrast
from napari_ssdpc.reconstruction.instrument_notices import condenser_notice
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.multislice import Source
from napari_ssdpc.simulation.sample_free import flat_frame, white_frame

NOMINAL = Optics.paper().replace(condenser_na=0.25)


def _notices(rec, frames) -> list[str]:
    """The notices said while ``rec`` reconstructs ``frames`` (one message per warning)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for frame in frames:
            rec.reconstruct(frame)
    return [str(w.message) for w in caught if issubclass(w.category, SsdpcWarning) and "fit-optics" in str(w.message)]


def test_views_out_of_focus_are_said_on_every_frame(synthetic_series):
    """A calibration whose white frame showed blurred rims: each frame says so, and its metadata
    holds the notice; the same calibration with the views' defocus in its optics (as `ssdpc
    fit-optics` writes it) says nothing."""
    optics, cal, flat, frames, _ = synthetic_series
    config = RunConfig.of(optics, method="wotf", z_min_um=0, z_max_um=0)
    blurred = dataclasses.replace(cal, rim_defocus_waves=0.47)
    rec = Reconstructor(config, blurred, flat=flat)
    said = _notices(rec, frames[:2])
    assert len(said) == 2 and all("0.47 waves" in s and "white frame" in s for s in said)
    with pytest.warns(SsdpcWarning, match="fit-optics"):
        assert rec.reconstruct(frames[0]).settings["instrument_notices"] == rec.notices == [said[0]]
    terms = tuple(LensletTerms(row=ln.row, col=ln.col, defocus_waves=0.47) for ln in cal.lenslets)
    fitted = dataclasses.replace(blurred, optics=cal.optics.replace(aberrations=Aberrations(lenslets=terms)))
    assert Reconstructor(config, fitted, flat=flat).notices == []
    assert Reconstructor(config, cal, flat=flat).notices == []  # rims in focus (measured 0.09 waves)


@pytest.fixture(scope="module")
def instrument():
    grid = Grid.nominal(NOMINAL, axis_offset_px=(2.3, -1.4), rotation_deg=0.3)
    cal = calibrate(white_frame(NOMINAL, grid=grid, rng=1), NOMINAL)
    return grid, cal, ViewContrast(NOMINAL, cal)


@pytest.mark.parametrize(
    "offset, uneven, said",
    [((0.01, -0.005), 0.0, True), ((0.0, 0.0), 0.03, False), ((0.004, 0.0), 0.0, False)],
    ids=["off-axis", "centred-lenslets-uneven", "within-tolerance"],
)
def test_a_condenser_off_axis_is_said(instrument, offset, uneven, said):
    """A flat lit by a condenser 0.011 NA off axis is said (naming fit-optics and the centre); a
    centred one is not, also with lenslets that transmit 3 % unevenly (their centre read within
    0.0011), nor one 0.004 off; optics that put the condenser where it is say nothing."""
    grid, cal, views = instrument
    truth = NOMINAL.replace(aberrations=Aberrations(condenser_offset_na=offset))
    levels, _ = views.lenslet_levels(flat_frame(truth, grid=grid, rng=2, source=Source(step=4)))
    levels = levels * (1 + uneven * np.random.default_rng(5).standard_normal(len(levels)))
    note = condenser_notice(levels, cal.lenslets, NOMINAL)
    assert (note is not None) == said
    if said:
        assert "ssdpc fit-optics" in note and "(+0.010, -0.005) NA" in note and "\n" not in note
        assert condenser_notice(levels, cal.lenslets, truth) is None
