"""A calibration with the instrument's aberrations gives them to every reconstruction made with it;
optics that give other aberrations are refused in one line (docs/aberrations.md)."""

import dataclasses

import pytest

from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.settings.config import RunConfig

FITTED = Aberrations(
    objective_zernike_waves=(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.3),
    lenslets=(LensletTerms(row=0, col=0, defocus_waves=0.2),),
)


@pytest.fixture(scope="module")
def fitted(synthetic_series, tmp_path_factory):
    optics, cal, flat = synthetic_series[:3]
    path = tmp_path_factory.mktemp("fitted") / "cal.json"
    dataclasses.replace(cal, optics=cal.optics.replace(aberrations=FITTED)).to_json(path)
    return optics, Calibration.from_json(path), flat


def test_the_calibrations_aberrations_are_used(fitted):
    optics, cal, flat = fitted
    assert cal.optics.aberrations == FITTED  # kept through the JSON file
    config = RunConfig.of(optics, z_min_um=0, z_max_um=0)
    rec = Reconstructor(config, cal, flat=flat)
    assert rec.optics.aberrations == FITTED and rec.optics.medium_index == optics.medium_index
    assert rec.views.optics.aberrations == FITTED
    assert rec.adopt(config)  # the same run configuration keeps the operators
    assert Job(config, cal, flat).metadata()["optics"]["aberrations"]["objective_zernike_waves"][10] == 0.3


def test_other_aberrations_in_the_optics_are_refused(fitted):
    optics, cal, flat = fitted
    other = optics.replace(aberrations=Aberrations(objective_zernike_waves=(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.1)))
    with pytest.raises(SsdpcError, match="different aberrations") as err:
        Reconstructor(RunConfig.of(other, z_min_um=0, z_max_um=0), cal, flat=flat)
    assert "\n" not in str(err.value) and "remove the optics' aberrations" in str(err.value)
    same = optics.replace(aberrations=FITTED)
    assert Reconstructor(RunConfig.of(same, z_min_um=0, z_max_um=0), cal, flat=flat).optics == same
