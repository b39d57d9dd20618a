"""Physics of the Fourier light-field microscope: design calculator, lattice geometry, pupils,
the wave-optics PSF (paper Eq. 6) and the weak-object transfer functions (paper Eqs. 2-4).

The names (listed in ``__init__.pyi``) load on first use: code that needs only the lattice (the
calibration, napari's dock) does not import the FFT and PSF modules.
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
