from .camera import Camera
from .imperfect import ArrayErrors
from .moving import moving_sample
from .multislice import Source
from .phantoms import bar_target, cell, pmma_bead, two_beads
from .sample_free import flat_frame, white_frame
from .simulate import Simulation

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
