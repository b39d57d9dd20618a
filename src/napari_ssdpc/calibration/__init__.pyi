from .measure import KINDS, calibrate
from .overlay import overlay_png
from .result import Calibration
from .view_focus import FocusFit, fit_view_focus
from .views import Views, extract_views, insert_views

__all__ = [
    "Calibration",
    "FocusFit",
    "KINDS",
    "Views",
    "calibrate",
    "extract_views",
    "fit_view_focus",
    "insert_views",
    "overlay_png",
]
