"""Signs on the white and flat frames of an instrument unlike its optics are said on every frame and
name `ssdpc fit-optics` (docs/aberrations.md); the condenser's notice is tested beside its fit
(test_condenser_fit.py)."""

import dataclasses
import warnings

import pytest

from napari_ssdpc.errors import SsdpcWarning
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.settings.config import RunConfig


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
