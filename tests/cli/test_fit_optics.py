"""``ssdpc fit-optics``: the condenser fitted to a flat frame of an instrument whose condenser is not
the nominal one, written into a new calibration that every reconstruction then uses."""

import hashlib

import pytest
import tifffile

from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.cli.main import main
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.reconstruction.checks import optics_in_use
from napari_ssdpc.settings.aberrations import Aberrations
from napari_ssdpc.simulation.multislice import Source
from napari_ssdpc.simulation.sample_free import flat_frame


@pytest.fixture(scope="module")
def real_flat(synthetic_series, tmp_path_factory):
    """A flat of the synthetic series' instrument at condenser NA 0.26 (its optics say 0.1, where only four
    lenslets are lit: too few to fit), 0.01 NA off axis."""
    optics = synthetic_series[0]
    truth = optics.replace(condenser_na=0.26, aberrations=Aberrations(condenser_offset_na=(0.01, -0.004)))
    grid = Grid.nominal(optics, axis_offset_px=(3.7, -2.2), rotation_deg=0.4)  # as the series' frames
    path = tmp_path_factory.mktemp("fit") / "flat_real.tif"
    tifffile.imwrite(path, flat_frame(truth, grid=grid, rng=7, source=Source(step=4)))
    return path, truth


def test_the_condenser_is_fitted_and_used(files, real_flat, tmp_path, capsys):
    flat, truth = real_flat
    before = hashlib.sha256((files / "cal.json").read_bytes()).hexdigest()
    out = tmp_path / "fitted.json"
    capsys.readouterr()
    assert main([str(a) for a in ("fit-optics", "--calibration", files / "cal.json", "--flat", flat, "-o", out)]) == 0
    text = capsys.readouterr().out
    assert "condenser NA" in text and "misfit" in text and "condenser off axis" in text
    assert hashlib.sha256((files / "cal.json").read_bytes()).hexdigest() == before
    fitted = Calibration.from_json(out)
    assert fitted.optics.condenser_na == pytest.approx(truth.condenser_na, abs=0.002)
    assert fitted.optics.aberrations.condenser_offset_na == pytest.approx((0.01, -0.004), abs=0.002)
    assert fitted.optics_fit["condenser"]["rms_after"] < fitted.optics_fit["condenser"]["rms_before"] / 5
    # the optics file still names the NA the fit corrected: the fitted condenser is used
    nominal = Calibration.from_json(files / "cal.json").optics
    used = optics_in_use(nominal, fitted)
    assert used.condenser_na == fitted.optics.condenser_na and used.source_centre == fitted.optics.source_centre
    # optics that name another condenser NA are a new setting: kept
    assert optics_in_use(nominal.replace(condenser_na=0.2), fitted).condenser_na == 0.2
    # with the white frame: each view's focus, in focus here (no notice)
    argv = ("fit-optics", "--calibration", files / "cal.json", "--flat", flat, "--white", files / "white.tif")
    assert main([str(a) for a in (*argv, "-o", tmp_path / "focus.json")]) == 0
    text = capsys.readouterr().out
    assert "view defocus |d| 0.0" in text and "blurred" not in text


@pytest.mark.parametrize(
    "which, words",
    [
        ("white", "does not determine the condenser"),
        ("flat", "only 4 lenslets inside the pupil are lit"),
        ("same", "calibration"),
        ("missing", "missing.tif"),
    ],
)
def test_fit_optics_bad_input_is_one_line_and_writes_nothing(cli, files, sums, tmp_path, which, words):
    flat = {"white": files / "white.tif", "missing": tmp_path / "missing.tif"}.get(which, files / "flat.tif")
    out = files / "cal.json" if which == "same" else tmp_path / "fitted.json"
    rc, line = cli(["fit-optics", "--calibration", files / "cal.json", "--flat", flat, "-o", out])
    assert rc == 2 and words in line
    assert which == "same" or not out.exists()


def test_bead_options_without_a_bead_frame_are_refused(cli, files, real_flat, tmp_path):
    out = tmp_path / "fitted.json"
    flat, _ = real_flat
    rc, line = cli(["fit-optics", "--calibration", files / "cal.json", "--flat", flat, "--bead-ri", 1.46, "-o", out])
    assert rc == 2 and "give the frame (FRAME)" in line and not out.exists()
