"""Measurements on reconstructed volumes: objects segmented from Δn, measured, linked over time."""

import lazy_loader as _lazy

# The public names are listed in __init__.pyi; each module loads on first use.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
