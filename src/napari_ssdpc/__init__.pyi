from ._version import SOFTWARE, __version__
from .analysis.table import measure_result
from .calibration import Calibration, Views, calibrate, extract_views, insert_views, overlay_png
from .errors import Cancelled, SsdpcError, SsdpcWarning
from .io import read_frame, write_ome_tiff
from .reconstruction import Reconstructor, Result
from .settings import Optics, ReconstructionSettings, RunConfig
from .simulation import bar_target, cell, flat_frame, moving_sample, pmma_bead, two_beads, white_frame
from .simulation.simulate import simulate

__all__ = [
    "SOFTWARE",
    "Calibration",
    "Cancelled",
    "Optics",
    "ReconstructionSettings",
    "Reconstructor",
    "Result",
    "RunConfig",
    "SsdpcError",
    "SsdpcWarning",
    "Views",
    "__version__",
    "bar_target",
    "calibrate",
    "cell",
    "extract_views",
    "flat_frame",
    "insert_views",
    "measure_result",
    "moving_sample",
    "overlay_png",
    "pmma_bead",
    "read_frame",
    "simulate",
    "two_beads",
    "white_frame",
    "write_ome_tiff",
]
