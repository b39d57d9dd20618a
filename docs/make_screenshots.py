"""Screenshots for docs/napari.md, made with the plugin's own widgets on the simulated PMMA bead.

    xvfb-run -a python docs/make_screenshots.py          # headless (or run it on a desktop)

Writes docs/images/napari_calibration.png, napari_3d.png, napari_orthogonal.png and
napari_profile.png. It follows the walk-through of docs/napari.md step by step (sample data,
Optics, Calibrate, Operators, Reconstruct, Line profile), with a z range of -40..40 µm every 2 µm
so that it runs in about a minute (plus ~30 s the first time, to simulate the bead).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "images"
Z = (-40.0, 40.0)
DZ = 2.0


def wait_for(app, runner, timeout_s=600):
    """Process Qt events until the widget's job has finished."""
    import time

    t0 = time.perf_counter()
    while runner.worker is not None:
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
    from qtpy.QtWidgets import QApplication

    from napari_ssdpc._napari.profiles import ProfileWidget
    from napari_ssdpc._napari.widgets import CalibrateWidget, OperatorsWidget, OpticsWidget, ReconstructWidget

    OUT.mkdir(exist_ok=True)
    napari.settings.get_settings().application.gui_notification_level = "error"  # no toasts in the pictures
    viewer = napari.Viewer(title="napari-ssdpc")
    app = QApplication.instance()
    viewer.window._qt_window.resize(1800, 1100)

    # 1. sample data and optics
    viewer.open_sample("napari-ssdpc", "pmma_bead")
    optics_w = OpticsWidget(viewer)
    docks = {"optics": viewer.window.add_dock_widget(optics_w, name="1. Optics", area="right")}
    viewer.layers.selection.active = viewer.layers["PMMA bead"]
    optics_w._from_layer()

    # 2. calibrate on the white frame
    cal_w = CalibrateWidget(viewer)
    docks["calibrate"] = viewer.window.add_dock_widget(cal_w, name="2. Calibrate", area="right", tabify=True)
    cal_w.image.value = viewer.layers["PMMA bead white"]
    cal_w.run()
    wait_for(app, cal_w.runner)
    print(cal_w.status.value)
    white = viewer.layers["PMMA bead white"]
    white.visible = True
    viewer.layers["PMMA bead"].visible = False
    g = cal_w.calibration.grid
    viewer.camera.center = (g.axis_px[1], g.axis_px[0])
    viewer.camera.zoom = 0.9 * viewer.window._qt_viewer.canvas.size[1] / (7 * g.pitch_px)
    docks["calibrate"].raise_()
    app.processEvents()
    grab(viewer, OUT / "napari_calibration.png")

    # 3. operators, 4. reconstruct (RI + phase)
    op_w = OperatorsWidget(viewer)
    rec_w = ReconstructWidget(viewer)
    docks["operators"] = viewer.window.add_dock_widget(op_w, name="3. Operators", area="right", tabify=True)
    docks["reconstruct"] = viewer.window.add_dock_widget(rec_w, name="4. Reconstruct", area="right", tabify=True)
    op_w.calibration.value = viewer.layers["PMMA bead white EI circles"]
    op_w.z_min.value, op_w.z_max.value, op_w.dz.value = Z[0], Z[1], DZ
    op_w.run()
    wait_for(app, op_w.runner)
    rec_w.raw.value = viewer.layers["PMMA bead"]
    rec_w.flat.value = viewer.layers["PMMA bead flat"]
    rec_w.run()
    wait_for(app, rec_w.runner)
    print(rec_w.status.value)
    ri = viewer.layers["PMMA bead RI"]

    # the RI volume in 3D (minimum-intensity projection: the bead has a lower index than the oil)
    viewer.dims.ndisplay = 3
    viewer.axes.visible = True  # z, y, x arrows in the corner
    viewer.reset_view(layers=[ri])
    viewer.camera.angles = (-20, 35, 140)
    docks["reconstruct"].raise_()
    app.processEvents()
    grab(viewer, OUT / "napari_3d.png")

    # orthogonal slices through the bead centre: xy, xz, yz (dims order changed, as a user would)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    viewer.dims.ndisplay = 2
    viewer.axes.visible = False
    centre = np.round(ri.world_to_data((0.0, 0.0, 0.0))).astype(int)
    panels = []
    for order, title in (((0, 1, 2), "xy (z = 0 µm)"), ((1, 0, 2), "xz (y = 0 µm)"), ((2, 0, 1), "yz (x = 0 µm)")):
        viewer.dims.order = order
        viewer.dims.current_step = tuple(int(c) for c in centre)
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

    # 5. line profiles: an xy line through the bead, and an axial (xz) line drawn in the xz view
    prof = ProfileWidget(viewer)
    viewer.window.add_dock_widget(prof, name="5. Line profile", area="right", tabify=True).raise_()
    prof.image.value = ri
    lines = prof.new_line_layer()
    to_vox = lambda p: (np.asarray(p) - ri.translate) / ri.scale  # noqa: E731, RUF100
    lines.add_lines(np.stack([to_vox((0.0, 0.0, -30.0)), to_vox((0.0, 0.0, 30.0))]))
    lines.add_lines(np.stack([to_vox((-36.0, 0.0, 0.0)), to_vox((36.0, 0.0, 0.0))]))
    lines.mode = "pan_zoom"
    viewer.dims.order = (1, 0, 2)  # the xz view: the axial line lies in it
    viewer.dims.current_step = tuple(int(c) for c in centre)
    viewer.reset_view(layers=[ri])
    app.processEvents()
    grab(viewer, OUT / "napari_profile.png")
    viewer.close()


if __name__ == "__main__":
    main()
