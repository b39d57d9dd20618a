"""The package version, and the stamp every file written by napari-ssdpc carries."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("napari-ssdpc")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"

#: Written into OME descriptions, the TIFF Software tag and PNG text: how ``io.paths.is_ours``
#: tells our files from a user's.
SOFTWARE = f"napari-ssdpc {__version__}"
