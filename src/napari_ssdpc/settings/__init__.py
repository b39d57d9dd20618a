"""Settings: the instrument, the reconstruction settings and the run configuration.

Pydantic models with strict types, units in the field names, value ranges in one place and
one-line errors that name the key, the value and the fix.
"""

from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.lenslets import Lenslet
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.parts import MLA, Objective, Sensor
from napari_ssdpc.settings.reconstruction import ReconstructionSettings

__all__ = [
    "MLA",
    "Aberrations",
    "Lenslet",
    "LensletTerms",
    "Objective",
    "Optics",
    "ReconstructionSettings",
    "RunConfig",
    "Sensor",
]
