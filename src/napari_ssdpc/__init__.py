"""napari-ssdpc: single-shot 3D quantitative phase imaging with a Fourier light-field microscope."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("napari-ssdpc")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.settings.optics import Optics

__all__ = ["Optics", "SsdpcError", "SsdpcWarning", "__version__"]
