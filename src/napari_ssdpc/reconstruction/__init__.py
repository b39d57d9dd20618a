"""Reconstruction: from a raw frame and its calibration to the RI volume (paper Eqs. 1-7).

:class:`Reconstructor` builds the operators once from a run configuration and reconstructs frame
after frame with the chosen phase method of the registry :data:`METHODS` ('tv', 'wotf', 'rl'),
each implementing :class:`PhaseMethod`.
"""

import lazy_loader as _lazy

# The public names are listed in __init__.pyi; each module loads on first use.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
