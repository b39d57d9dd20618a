"""The package version, and the stamp every file written by napari-ssdpc carries."""

__version__ = "0.1.0"

#: Written into OME descriptions, the TIFF Software tag and PNG text: how ``io.paths.is_ours``
#: tells our files from a user's.
SOFTWARE = f"napari-ssdpc {__version__}"
