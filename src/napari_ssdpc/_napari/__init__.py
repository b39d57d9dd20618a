"""The napari plugin: readers, writer, sample data and the dock widgets (the only package that
imports napari, magicgui or Qt). napari loads the modules named in ``napari.yaml``."""

import lazy_loader as _lazy

# Submodules (listed in __init__.pyi), imported by napari as the manifest names them: nothing GUI
# loads before that.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
