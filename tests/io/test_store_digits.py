"""A series store that keeps a given number of decimal digits: smaller, within 10^-digits of the
exact store, and a resume with another choice is refused."""

import numpy as np
import pytest

from napari_ssdpc.cli.main import main
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.io.ome_zarr import read_ome_zarr
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import ZarrSink
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.validation.cases import run_config

SETTINGS = dict(z=(-20.0, 20.0), dz=10.0, rl={"iterations": 2}, method="rl")


def _bytes(store):
    return sum(p.stat().st_size for p in (store / "ri" / "0").iterdir() if p.name[0].isdigit())


@pytest.fixture(scope="module")
def stores(synthetic_series, tmp_path_factory):
    optics, cal, flat, frames, _ = synthetic_series
    d = tmp_path_factory.mktemp("digits")
    config = run_config(optics, **SETTINGS)
    rec = Job(config, cal, flat).build()
    out = {}
    for digits in (None, 5, 3):
        cfg = RunConfig(optics=config.optics, reconstruction=config.reconstruction, outputs={"store_digits": digits})
        job = Job(cfg, cal, flat)
        out[digits] = d / f"d{digits}.zarr"
        Pipeline(job, reconstructor=rec).run(frames[:3], ZarrSink(out[digits], ["phase"]), progress=False)
    return out, frames, (optics, cal, flat)


@pytest.mark.parametrize("digits", [5, 3])
def test_a_store_keeps_the_digits_asked_for(stores, digits):
    out, _, _ = stores
    for name in ("ri", "phase"):
        exact = read_ome_zarr(out[None], name)[0][:]
        kept = read_ome_zarr(out[digits], name)[0][:]
        err = np.abs(kept - exact).max()
        assert 0 < err <= 10.0**-digits  # rounded, within its digits
    assert _bytes(out[digits]) < _bytes(out[None])


def test_a_resume_with_other_digits_is_refused(stores):
    out, frames, (optics, cal, flat) = stores
    cfg = RunConfig(optics=optics, reconstruction=run_config(optics, **SETTINGS).reconstruction)
    with pytest.raises(SsdpcError, match="holds a reconstruction with other store digits; choose a new output path"):
        Pipeline(Job(cfg, cal, flat)).run(frames[:3], ZarrSink(out[5], ["phase"]), progress=False)


def test_store_digits_belongs_to_a_store(stores, tmp_path, capsys):
    _, frames, (optics, cal, flat) = stores
    import tifffile

    tifffile.imwrite(tmp_path / "f.tif", frames[0])
    tifffile.imwrite(tmp_path / "flat.tif", flat)
    cal.to_json(tmp_path / "cal.json")
    base = ["reconstruct", str(tmp_path / "f.tif"), "--calibration", str(tmp_path / "cal.json")]
    assert main(base + ["--store-digits", "5", "-o", str(tmp_path / "one.ome.tif")]) == 2
    assert "give -o OUT.zarr" in capsys.readouterr().err
    assert main(base + ["--store-digits", "0", "-o", str(tmp_path / "s.zarr")]) == 2
    err = capsys.readouterr().err
    assert "store_digits" in err and err.count("\n") == 1


def test_digits_that_cannot_hold_the_samples_delta_n_to_one_percent_warn(stores, tmp_path):
    import math
    import warnings

    from napari_ssdpc.errors import SsdpcWarning

    out, frames, (optics, cal, flat) = stores
    peak = float(np.nanmax(np.abs(read_ome_zarr(out[None], "ri")[0][:1] - optics.medium_index)))
    need = math.ceil(-math.log10(0.01 * peak))
    config = run_config(optics, **SETTINGS)

    def run(digits, name):
        cfg = RunConfig(optics=config.optics, reconstruction=config.reconstruction, outputs={"store_digits": digits})
        Pipeline(Job(cfg, cal, flat)).run(frames[:2], ZarrSink(tmp_path / name), progress=False)

    with pytest.warns(SsdpcWarning, match=f"--store-digits {need - 1} keeps values to .* use --store-digits {need}"):
        run(need - 1, "coarse.zarr")
    with warnings.catch_warnings():
        warnings.simplefilter("error", SsdpcWarning)
        run(need, "fine.zarr")
