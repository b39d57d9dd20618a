"""The independent forward simulator: phantoms, multislice propagation, lenslets, camera.

It keeps its own discretisation, so that the reconstruction is checked against a model it does
not share (no inverse crime). One frame end to end: ``simulation.simulate.simulate`` (the
module ``simulate`` keeps its name here, so ``from napari_ssdpc.simulation import simulate``
gives the module).
"""

from napari_ssdpc.simulation.camera import Camera
from napari_ssdpc.simulation.imperfect import ArrayErrors
from napari_ssdpc.simulation.multislice import Source
from napari_ssdpc.simulation.phantoms import bar_target, cell, moving_sample, pmma_bead, two_beads
from napari_ssdpc.simulation.sample_free import flat_frame, white_frame
from napari_ssdpc.simulation.simulate import Simulation

__all__ = [
    "ArrayErrors",
    "Camera",
    "Simulation",
    "Source",
    "bar_target",
    "cell",
    "flat_frame",
    "moving_sample",
    "pmma_bead",
    "two_beads",
    "white_frame",
]
