"""Calibration: the lenslet lattice, each EI's centre and the optical axis, measured on a frame.

``calibrate(frame, optics)`` returns a :class:`Calibration` (JSON round trip, overlay PNG);
``extract_views`` cuts the elementary images out of a raw frame on the object grid.
"""

import lazy_loader as _lazy

# The public names are listed in __init__.pyi; each module loads on first use.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
