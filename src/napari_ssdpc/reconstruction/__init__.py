"""Reconstruction: from a raw frame and its calibration to the RI volume (paper Eqs. 1-7).

:class:`Reconstructor` builds the operators once and reconstructs frame after frame with the
chosen method ('tv', 'wotf' or 'rl'); :data:`QUANTITIES` is the registry of what it outputs.
"""

from napari_ssdpc.reconstruction.backend import get_backend
from napari_ssdpc.reconstruction.outputs import QUANTITIES, Quantity
from napari_ssdpc.reconstruction.pipeline import Reconstructor, Result
from napari_ssdpc.reconstruction.regularised import TvInversion
from napari_ssdpc.reconstruction.tv_report import TvReport
from napari_ssdpc.reconstruction.wotf import WotfInversion

__all__ = [
    "QUANTITIES",
    "Quantity",
    "Reconstructor",
    "Result",
    "TvInversion",
    "TvReport",
    "WotfInversion",
    "get_backend",
]
