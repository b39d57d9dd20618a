"""The calibration overlays of docs/calibration.md: a clean white frame and a hard one.

    python docs/make_calibration_figures.py

The hard frame is what real instruments give: a misaligned array with per-lenslet offsets of up to
2 % of the pitch and a 0.6° shear, a lens-mount shadow notching every EI rim, bright sample content
in every EI, strong vignetting and 8-bit quantisation. Writes docs/images/calibration_overlay.png
and docs/images/calibration_overlay_hard.png and prints how far the measured centres are from the
truth.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.calibration.overlay import overlay_png
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation import imperfect
from napari_ssdpc.simulation.camera import Camera
from napari_ssdpc.simulation.imaging import array_as_built
from napari_ssdpc.simulation.sample_free import white_frame, white_intensity

OUT = Path(__file__).resolve().parent / "images"


def worst_error(cal, centres, lenslets) -> float:
    """Largest distance (px) of a measured EI centre from the truth, over lenslets mostly in the pupil."""
    d = np.hypot(*(cal.centres_px[:, None, :] - centres[None, :, :]).transpose(2, 0, 1)).min(axis=0)
    return float(d[np.array([ln.fraction for ln in lenslets]) >= 0.5].max())


def main():
    optics = Optics.paper()
    grid = Grid.nominal(optics, axis_offset_px=(30.3, -12.7), rotation_deg=2.3)
    white = white_frame(optics, grid=grid, rng=1)
    cal = calibrate(white, optics)
    overlay_png(white, cal, OUT / "calibration_overlay.png")
    _, _, truth, centres = array_as_built(optics, grid, None)
    print(f"clean white frame: worst EI centre {worst_error(cal, centres, truth):.3f} px")

    array = imperfect.ArrayErrors(offset_frac=0.02, shear_deg=0.6, seed=4)
    camera = Camera(bit_depth=8, gain_adu_per_e=0.015, dark_offset_adu=10)
    grid, camera, truth, centres = array_as_built(optics, grid, camera, array)
    intensity = white_intensity(optics, grid, camera, array=array)
    r = optics.ei_radius_px
    intensity = imperfect.notch(intensity, centres, r)
    intensity = imperfect.content(intensity, centres, r, contrast=0.6)
    intensity = imperfect.vignetting(intensity, strength=0.5)
    hard = camera.apply(intensity, camera.rng(7))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = calibrate(hard, optics)
    overlay_png(hard, cal, OUT / "calibration_overlay_hard.png")
    print(
        f"hard frame ({cal.kind}): worst EI centre {worst_error(cal, centres, truth):.3f} px, "
        f"largest deviation from the lattice {cal.max_deviation_px:.2f} px"
    )


if __name__ == "__main__":
    main()
