"""The napari plugin: readers, writer, sample data and the dock widgets (the only package that
imports napari, magicgui or Qt). napari loads the modules named in ``napari.yaml``."""

# Submodules, imported by napari as the manifest names them (nothing GUI loads before that).
__all__ = ["layers", "notify", "placement", "profiles", "reader", "sample_data", "widgets", "writer"]
