"""Reconstruction: from a raw frame and its calibration to the RI volume (paper Eqs. 1-7).

:class:`Reconstructor` builds the operators once and reconstructs frame after frame with the
chosen method ('tv', 'wotf' or 'rl'); :data:`QUANTITIES` is the registry of what it outputs.
"""

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "QUANTITIES": "napari_ssdpc.reconstruction.outputs",
    "Quantity": "napari_ssdpc.reconstruction.outputs",
    "Reconstructor": "napari_ssdpc.reconstruction.pipeline",
    "Result": "napari_ssdpc.reconstruction.pipeline",
    "TvInversion": "napari_ssdpc.reconstruction.regularised",
    "TvReport": "napari_ssdpc.reconstruction.tv_report",
    "WotfInversion": "napari_ssdpc.reconstruction.wotf",
    "get_backend": "napari_ssdpc.reconstruction.backend",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    """Load a public name's module on first use (the package imports nothing heavy up front)."""
    if name in _EXPORTS:
        from importlib import import_module

        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
