"""Calibration: the lenslet lattice, each EI's centre and the optical axis, measured on a frame.

``calibrate(frame, optics)`` returns a :class:`Calibration` (JSON round trip, overlay PNG);
``extract_views`` cuts the elementary images out of a raw frame on the object grid.
"""

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "Calibration": "napari_ssdpc.calibration.result",
    "KINDS": "napari_ssdpc.calibration.calibrate",
    "Views": "napari_ssdpc.calibration.result",
    "calibrate": "napari_ssdpc.calibration.calibrate",
    "extract_views": "napari_ssdpc.calibration.views",
    "insert_views": "napari_ssdpc.calibration.views",
    "overlay_png": "napari_ssdpc.calibration.overlay",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    """Load a public name's module on first use (the package imports nothing heavy up front)."""
    if name in _EXPORTS:
        from importlib import import_module

        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
