"""Screenshots for docs/napari.md, made through the ssDPC dock on the PMMA bead sample, with the
timings a user meets (sample open, calibration, reconstruction, the longest GUI stall).

    xvfb-run -a python docs/make_screenshots.py              # into docs/_screenshots/ (git ignores it)
    xvfb-run -a python docs/make_screenshots.py --update-docs  # into docs/images/, for the docs

It follows the walk-through of docs/napari.md step by step in a 1280 x 800 window (sample data,
Optics, Calibrate, Method, Reconstruct, Profile), with a z range of -40..40 µm every 2 µm.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

DOCS = Path(__file__).resolve().parent
OUT = DOCS / ("images" if "--update-docs" in sys.argv else "_screenshots")
Z = (-40.0, 40.0)
DZ = 2.0
WINDOW = (1280, 800)


class StallMeter:
    """The longest gap between ticks of a 20 ms Qt timer: how long the GUI was blocked."""

    def __init__(self):
        from qtpy.QtCore import QTimer

        self.last, self.worst, self.where, self.label = time.perf_counter(), 0.0, "", "start"
        self.timer = QTimer()
        self.timer.timeout.connect(self._tick)
        self.timer.start(20)

    def _tick(self):
        now = time.perf_counter()
        if now - self.last > self.worst:
            self.worst, self.where = now - self.last, self.label
        self.last = now


def wait_for(app, runner=None, timeout_s=600):
    """Process Qt events until the widget's job has finished (when given) and what waits for a
    turn of the event loop of its own is shown."""
    import time

    from napari_ssdpc._napari import turns

    t0 = time.perf_counter()
    while (runner is not None and runner.worker is not None) or turns.pending():
        app.processEvents()
        time.sleep(0.02)
        if time.perf_counter() - t0 > timeout_s:
            raise RuntimeError("job did not finish")
    app.processEvents()


def grab(viewer, path, canvas_only=False):
    """Screenshot of the whole window (docks included) or of the canvas only."""
    from skimage.io import imsave

    img = viewer.screenshot(canvas_only=canvas_only, flash=False)
    imsave(path, img, check_contrast=False)
    print(f"wrote {path}")
    return img


def main():
    import napari
    from napari.settings import get_settings
    from qtpy.QtWidgets import QApplication

    from napari_ssdpc._napari.placement import scale_bar

    OUT.mkdir(exist_ok=True)
    get_settings().application.gui_notification_level = "error"  # no toasts in the pictures
    viewer = napari.Viewer(title="napari-ssdpc")
    app = QApplication.instance()
    window = viewer.window._qt_window
    window.resize(*WINDOW)
    stalls = StallMeter()
    times = {}

    # the dock, then the sample data and its optics
    app.processEvents()
    stalls.label, t0 = "opening the dock", time.perf_counter()
    _, dock = viewer.window.add_plugin_dock_widget("napari-ssdpc", "ssDPC")
    app.processEvents()
    times["dock open"] = time.perf_counter() - t0
    tabs = dock.tabs
    t0 = time.perf_counter()
    stalls.label = "opening the sample"
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    wait_for(app)
    times["sample open"] = time.perf_counter() - t0
    stalls.label = "adopting the sample's optics"
    viewer.layers.selection.active = viewer.layers["PMMA bead"]
    tabs["Optics"]._from_layer()
    app.processEvents()

    # calibrate on the white frame
    cal_w = tabs["Calibrate"]
    dock.tab_widget.setCurrentIndex(list(tabs).index("Calibrate"))
    cal_w.image.value = viewer.layers["PMMA bead white"]
    stalls.label, t0 = "calibrating", time.perf_counter()
    cal_w.run()
    wait_for(app, cal_w.runner)
    times["calibration"] = time.perf_counter() - t0
    print(cal_w.status.value)
    white = viewer.layers["PMMA bead white"]
    white.visible = True
    viewer.layers["PMMA bead"].visible = False
    g = cal_w.calibration.grid
    viewer.camera.center = tuple(white.data_to_world((g.axis_px[1], g.axis_px[0])))
    viewer.camera.zoom = 0.9 * viewer.window._qt_viewer.canvas.size[1] / (7 * g.pitch_px * white.scale[-1])
    app.processEvents()
    grab(viewer, OUT / "napari_calibration.png")

    # method and reconstruct (RI)
    op_w, rec_w = tabs["Method"], tabs["Reconstruct"]
    dock.tab_widget.setCurrentIndex(list(tabs).index("Method"))
    op_w.calibration.value = viewer.layers["PMMA bead white EI circles"]
    op_w.z_min.value, op_w.z_max.value, op_w.dz.value = Z[0], Z[1], DZ
    op_w.sign.value = "lighter"  # PMMA in oil
    dock.tab_widget.setCurrentIndex(list(tabs).index("Reconstruct"))
    rec_w.raw.value = viewer.layers["PMMA bead"]
    rec_w.flat.value = viewer.layers["PMMA bead flat"]
    stalls.label, t0 = "reconstructing", time.perf_counter()
    rec_w.run()
    wait_for(app, rec_w.runner)
    times["operators + reconstruction"] = time.perf_counter() - t0
    stalls.label = "inspecting"
    print(rec_w.status.value)
    ri = viewer.layers["PMMA bead RI"]

    # the RI volume in 3D (minimum-intensity projection: the bead has a lower index than the oil)
    viewer.dims.ndisplay = 3
    viewer.axes.visible = True  # z, y, x arrows in the corner
    viewer.reset_view(layers=[ri])
    viewer.camera.angles = (-20, 35, 140)
    dock.tab_widget.setCurrentIndex(list(tabs).index("Slices"))  # xz and yz sections beside the volume
    tabs["Slices"].layer.value = ri
    tabs["Slices"].update()
    app.processEvents()
    grab(viewer, OUT / "napari_3d.png")

    # orthogonal slices through the bead centre: xy, xz, yz (dims order changed, as a user would)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    viewer.dims.ndisplay = 2
    viewer.axes.visible = False
    panels = []
    for order, title in (((0, 1, 2), "xy (z = 0 µm)"), ((1, 0, 2), "xz (y = 0 µm)"), ((2, 0, 1), "yz (x = 0 µm)")):
        viewer.dims.order = order
        viewer.dims.set_point([0, 1, 2], (0.0, 0.0, 0.0))  # through the bead centre (world µm)
        viewer.reset_view(layers=[ri])
        app.processEvents()
        panels.append((viewer.screenshot(canvas_only=True, flash=False), title))
    viewer.dims.order = (0, 1, 2)
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.6))
    for ax, (img, title) in zip(axes, panels):
        ax.imshow(img)
        ax.set_title(title)
        ax.axis("off")
    lo, hi = ri.contrast_limits
    fig.suptitle(
        f"RI layer, colormap {ri.colormap.name}, {lo:.4f} (blue) … {hi:.4f} (red); "
        "napari canvas screenshots with the dims order changed"
    )
    fig.tight_layout()
    fig.savefig(OUT / "napari_orthogonal.png", dpi=90)
    print(f"wrote {OUT / 'napari_orthogonal.png'}")

    # line profiles: an xy line through the bead, and an axial (xz) line drawn in the xz view
    prof = tabs["Profile"]
    dock.tab_widget.setCurrentIndex(list(tabs).index("Profile"))
    prof.image.value = ri
    lines = prof.new_line_layer()
    to_vox = lambda p: (np.asarray(p) - ri.translate) / ri.scale  # noqa: E731, RUF100
    lines.add_lines(np.stack([to_vox((0.0, 0.0, -30.0)), to_vox((0.0, 0.0, 30.0))]))
    lines.add_lines(np.stack([to_vox((-36.0, 0.0, 0.0)), to_vox((36.0, 0.0, 0.0))]))
    lines.mode = "pan_zoom"
    viewer.dims.order = (1, 0, 2)  # the xz view: the axial line lies in it
    viewer.dims.set_point([0, 1, 2], (0.0, 0.0, 0.0))
    viewer.reset_view(layers=[ri])
    app.processEvents()
    grab(viewer, OUT / "napari_profile.png")
    size = window.size()
    print(
        "; ".join(f"{k} {v:.1f} s" for k, v in times.items())
        + f"; longest GUI stall {stalls.worst:.2f} s ({stalls.where}); window {size.width()} x {size.height()} px;"
        f" scale bar {'on' if scale_bar(viewer).visible else 'off'}"
    )
    viewer.close()


if __name__ == "__main__":
    main()
