"""From camera frame to RI layer in napari: the latency of the Reconstruct tab's camera source.

napari with the ssDPC dock, the shipped sample bead (paper optics at condenser NA 0.3, 24 lit views,
a 1024 px region) calibrated in the dock, z −40..40 µm every 1 µm (81 planes); a Micro-Manager
core (pymmcore-plus's pure-Python camera) serving noisy copies of the bead frame at 67 frames/s
(the paper records at 74) for ``--seconds`` per method; the dock's camera queue at its default
(2 frames: when the solver lags the oldest waiting frame is dropped). Per method: the frames
reconstructed and dropped, and the latency from a frame leaving the camera to its volume and to
its RI layer shown (median, max), as the dock's status gives them.

    xvfb-run -a python benchmarks/camera_latency.py [--methods wotf tv] [--seconds 20] [--json OUT.json]

Needs napari, pymmcore-plus and a display (Xvfb will do); docs/performance.md has the results.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' simulated camera

CAMERA_HZ = 1 / 0.015  # camera_sim.SimulatedCamera serves a frame every 15 ms


def _wait(widget, app) -> None:
    while widget.runner.worker is not None:
        app.processEvents()
        time.sleep(0.005)


def _stats(values) -> dict:
    v = list(values)
    return {"median_s": statistics.median(v), "max_s": max(v), "n": len(v)} if v else {"n": 0}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", nargs="+", default=["wotf", "tv"])
    ap.add_argument("--seconds", type=float, default=20.0, help="length of each acquisition, s")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    import napari
    import useq
    from qtpy.QtWidgets import QApplication

    from camera_sim import core_with
    from napari_ssdpc._napari import sample_data
    from napari_ssdpc.validation.bench import machine

    viewer = napari.Viewer(show=False)
    app = QApplication.instance()
    _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    tabs = {k.lower(): v for k, v in dock.tabs.items()}
    frame, _, _, optics = sample_data.bead_frames()
    for data, kw, kind in sample_data.pmma_bead_sample():
        getattr(viewer, f"add_{kind}")(data, **kw)
    tabs["optics"].set_optics(optics)
    cal, op, rc = tabs["calibrate"], tabs["method"], tabs["reconstruct"]
    cal.image.value = viewer.layers["PMMA bead white"]
    cal.run()
    _wait(cal, app)
    op.calibration.value = viewer.layers["PMMA bead white EI circles"]
    op.z_min.value, op.z_max.value, op.dz.value = -40.0, 40.0, 1.0
    rc.raw.value, rc.flat.value, rc.store.value = viewer.layers["PMMA bead"], viewer.layers["PMMA bead flat"], ""
    rng = np.random.default_rng(0)
    frames = np.stack([(frame * rng.normal(1.0, 0.01, frame.shape)).astype(frame.dtype) for _ in range(8)])
    loops = int(args.seconds * CAMERA_HZ)

    report: dict = {"machine": machine(), "camera_hz": CAMERA_HZ, "seconds": args.seconds, "rows": {}}
    for method in args.methods:
        op.method.value = method
        rc.run()  # the sample frame: the operators are built before the camera starts, as a user would
        _wait(rc, app)
        core = core_with(frames)
        rc.camera.start(core)
        t0 = time.perf_counter()
        acquisition = core.run_mda(useq.MDASequence(time_plan={"interval": 0, "loops": loops}))
        while acquisition.is_alive():
            app.processEvents()
            time.sleep(0.005)
        rc.camera.stop()  # the acquisition is over: the waiting frames are finished
        _wait(rc, app)
        row = {
            "frames_s": time.perf_counter() - t0,
            "status": rc.status.value,
            "to_volume": _stats(rc.camera.reconstructed_s),
            "to_layer": _stats(rc.camera.shown_s),
        }
        report["rows"][method] = row
        print(f"{method}: {row['status']}", flush=True)
        if args.json:
            args.json.write_text(json.dumps(report, indent=1, default=str))
    viewer.close()
    return report


if __name__ == "__main__":
    main()
