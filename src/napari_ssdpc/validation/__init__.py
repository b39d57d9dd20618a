"""Validation: metrics, phantom cases, figures, the demo, the reference path and the benchmark.

Nothing here runs when a frame is reconstructed.
"""

import lazy_loader as _lazy

# Submodules (listed in __init__.pyi), each loaded on first use: matplotlib and the simulator load
# only then.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
