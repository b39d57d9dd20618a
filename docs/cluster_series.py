"""A 50-frame series on a local Dask cluster of 2 workers against the serial run (docs/performance.md).

The first 20 frames of the cached moving sample at condenser NA 0.25 (see docs/warm_start_series.py),
repeated to 50 and written to a TIFF, reconstructed by 'wotf' over z −60..60 µm every 1 µm into
OME-Zarr stores: serially and with ``--workers 2``. Prints the wall times and the largest difference.

    python docs/cluster_series.py --cache /tmp/cases
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import tifffile

from napari_ssdpc.cli.main import main as ssdpc
from napari_ssdpc.io.ome_zarr import read_ome_zarr
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation import moving
from napari_ssdpc.validation import cases as val


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True, help="folder of the simulated series (.npz)")
    ap.add_argument("--frames", type=int, default=50)
    args = ap.parse_args(argv)
    optics = Optics.paper().replace(condenser_na=0.25)
    case = val.simulate_case("moving20", moving.moving_sample(20), optics, cache_dir=args.cache, source_step=4)
    frames = np.concatenate([case.frame] * (args.frames // len(case.frame) + 1))[: args.frames]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        tifffile.imwrite(d / "series.tif", frames, photometric="minisblack")
        tifffile.imwrite(d / "flat.tif", case.flat)
        tifffile.imwrite(d / "white.tif", case.white)
        case.optics.to_yaml(d / "optics.yaml")
        calibrate = ["calibrate", str(d / "white.tif"), "--optics", str(d / "optics.yaml"), "-o", str(d / "cal.json")]
        assert ssdpc(calibrate) == 0
        common = [str(d / "series.tif"), "--calibration", str(d / "cal.json"), "--flat", str(d / "flat.tif")]
        common += ["--method", "wotf", "--z", "-60", "60", "--dz", "1"]
        seconds = {}
        for name, extra in (("serial", []), ("workers2", ["--workers", "2"])):
            t0 = time.perf_counter()
            assert ssdpc(["reconstruct", *common, "-o", str(d / f"{name}.zarr"), *extra]) == 0
            seconds[name] = time.perf_counter() - t0
        a = read_ome_zarr(d / "serial.zarr")[0][:]
        b = read_ome_zarr(d / "workers2.zarr")[0][:]
        print(f"{args.frames} frames: serial {seconds['serial']:.1f} s, 2 workers {seconds['workers2']:.1f} s; ")
        print(f"largest |difference| of RI {np.abs(a - b).max():.2e}; identical: {np.array_equal(a, b)}")


if __name__ == "__main__":
    main()
