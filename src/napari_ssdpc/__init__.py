"""napari-ssdpc: single-shot 3D quantitative phase imaging with a Fourier light-field microscope.

The names a user works with are importable from here (``from napari_ssdpc import Optics,
calibrate, Reconstructor``); each loads on first use, so ``import napari_ssdpc`` stays light
(napari imports it to read the plugin's manifest). They are listed in ``__init__.pyi``.
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
