"""Calibration: the lenslet lattice, each EI's centre and the optical axis, measured on a frame.

``calibrate(frame, optics)`` returns a :class:`Calibration` (JSON round trip, overlay PNG);
``extract_views`` cuts the elementary images out of a raw frame on the object grid.
"""

from napari_ssdpc.calibration.calibrate import KINDS, calibrate
from napari_ssdpc.calibration.overlay import overlay_png
from napari_ssdpc.calibration.result import Calibration, Views
from napari_ssdpc.calibration.views import extract_views, insert_views

__all__ = ["KINDS", "Calibration", "Views", "calibrate", "extract_views", "insert_views", "overlay_png"]
