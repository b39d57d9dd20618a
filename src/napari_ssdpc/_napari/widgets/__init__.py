"""napari dock widgets: Optics, Calibrate, Operators, Reconstruct (the line profile is in
``_napari/profiles.py``).

The widgets are thin: they collect settings, call the core packages and turn the results into
layers. All widgets of one viewer share a ``Session`` (``session.py``); long work runs in
``jobs.py``'s workers with progress and Cancel.
"""

from napari_ssdpc._napari.widgets.calibrate import CalibrateWidget
from napari_ssdpc._napari.widgets.operators import OperatorsWidget
from napari_ssdpc._napari.widgets.optics import OpticsWidget
from napari_ssdpc._napari.widgets.reconstruct import ReconstructWidget
from napari_ssdpc._napari.widgets.session import Session, session_for

__all__ = ["CalibrateWidget", "OperatorsWidget", "OpticsWidget", "ReconstructWidget", "Session", "session_for"]
