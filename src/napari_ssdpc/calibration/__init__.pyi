from .measure import KINDS, calibrate
from .overlay import overlay_png
from .result import Calibration
from .views import Views, extract_views, insert_views

__all__ = [
    "Calibration",
    "KINDS",
    "Views",
    "calibrate",
    "extract_views",
    "insert_views",
    "overlay_png",
]
