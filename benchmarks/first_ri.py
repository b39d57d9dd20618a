"""Time to the first RI: what pressing Reconstruct on the bead sample does, with the dock's defaults.

The shipped bead sample (the paper's optics at condenser NA 0.3, a 1024 px region), calibrated on its
white frame (the Calibrate step, not timed); then, timed from the press: the operators of z −80..80 µm
every 1 µm (161 planes, the dock's defaults), the quick first answer napari shows at once (the
Tikhonov inverse `tv` starts from), and the `tv` answer (sign `auto` with its probes, 60
iterations) that replaces it. The same calls the dock's worker makes, without the GUI.

    python benchmarks/first_ri.py [--json OUT.json]

docs/napari.md has the results (targets on 2 quiet cores: 15 s and 60 s).
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings

from napari_ssdpc._napari import sample_data
from napari_ssdpc.calibration import calibrate
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.config import RunConfig


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", default=None, help="write the times here too")
    args = p.parse_args()
    frame, flat, white, optics = sample_data.bead_frames()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = calibrate(white, optics)
        t0 = time.perf_counter()
        rec = Reconstructor(RunConfig.of(optics), cal, flat=flat)
        built = time.perf_counter() - t0
        rec.first_answer(frame)
        first = time.perf_counter() - t0
        res = rec.reconstruct(frame)
        answer = time.perf_counter() - t0
    out = {
        "planes": int(res.delta_n.shape[0]),
        "operators_s": built,
        "first_answer_s": first,
        "tv_answer_s": answer,
        "load_average": os.getloadavg()[0],
        "cores": os.cpu_count(),
    }
    print(json.dumps(out, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
