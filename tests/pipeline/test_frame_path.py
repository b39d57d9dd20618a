"""The path of one frame through `ssdpc reconstruct`: each input is checked and cut into views once."""

import json

import numpy as np
import tifffile

from napari_ssdpc.cli.main import main
from napari_ssdpc.reconstruction import contrast


def test_ssdpc_reconstruct_cuts_the_flat_and_the_frame_into_views_once(synthetic_series, tmp_path, monkeypatch):
    optics, cal, flat, frames, _ = synthetic_series
    tifffile.imwrite(tmp_path / "frame.tif", frames[0])
    tifffile.imwrite(tmp_path / "flat.tif", flat)
    cal.to_json(tmp_path / "cal.json")
    cut = []
    real = contrast.ViewContrast._dark  # every frame's checks and dark offset, before its views are cut

    def counting(self, frame, name):
        cut.append(float(np.max(frame)))
        return real(self, frame, name)

    monkeypatch.setattr(contrast.ViewContrast, "_dark", counting)
    args = ["reconstruct", str(tmp_path / "frame.tif"), "--calibration", str(tmp_path / "cal.json")]
    args += ["--flat", str(tmp_path / "flat.tif"), "--z", "-20", "20", "--dz", "10", "--method", "wotf"]
    assert main([*args, "-o", str(tmp_path / "out.ome.tif")]) == 0
    # the flat, the frame: nothing is cut twice (the views' grid comes from the calibration alone)
    assert len(cut) == 2 and all(c > 0 for c in cut)
    # what the CLI wrote beside the volume is the job's one metadata (napari's stores use the same builder)
    from napari_ssdpc._version import SOFTWARE
    from napari_ssdpc.io.frames import tiff_info
    from napari_ssdpc.pipeline.job import Job
    from napari_ssdpc.settings.config import RunConfig

    desc = json.loads(tiff_info(tmp_path / "out.ome.tif").ome["Description"])
    meta = Job(RunConfig.of(optics), cal).metadata("frame.tif")
    assert meta["software"] == SOFTWARE and "lenslets" not in meta["calibration"]
    for key in ("software", "source", "optics", "medium_index", "calibration"):
        assert desc[key] == meta[key], key
