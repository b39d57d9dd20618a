"""napari-ssdpc: single-shot 3D quantitative phase imaging with a Fourier light-field microscope."""

from napari_ssdpc._version import SOFTWARE, __version__
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.settings.optics import Optics

__all__ = ["SOFTWARE", "Optics", "SsdpcError", "SsdpcWarning", "__version__"]
