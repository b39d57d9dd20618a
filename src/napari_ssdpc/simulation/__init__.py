"""The independent forward simulator: phantoms, multislice propagation, lenslets, camera.

It keeps its own discretisation, so that the reconstruction is checked against a model it does
not share (no inverse crime). One frame end to end: ``simulation.simulate.simulate`` (the
module ``simulate`` keeps its name here, so ``from napari_ssdpc.simulation import simulate``
gives the module).
"""

import lazy_loader as _lazy

# The public names are listed in __init__.pyi; each module loads on first use.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
