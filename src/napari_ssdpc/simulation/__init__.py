"""The independent forward simulator: phantoms, multislice propagation, lenslets, camera.

It keeps its own discretisation, so that the reconstruction is checked against a model it does
not share (no inverse crime). One frame end to end: ``simulation.simulate.simulate`` (the
module ``simulate`` keeps its name here, so ``from napari_ssdpc.simulation import simulate``
gives the module).
"""

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "ArrayErrors": "napari_ssdpc.simulation.imperfect",
    "Camera": "napari_ssdpc.simulation.camera",
    "Simulation": "napari_ssdpc.simulation.simulate",
    "Source": "napari_ssdpc.simulation.multislice",
    "bar_target": "napari_ssdpc.simulation.phantoms",
    "cell": "napari_ssdpc.simulation.phantoms",
    "flat_frame": "napari_ssdpc.simulation.sample_free",
    "moving_sample": "napari_ssdpc.simulation.phantoms",
    "pmma_bead": "napari_ssdpc.simulation.phantoms",
    "two_beads": "napari_ssdpc.simulation.phantoms",
    "white_frame": "napari_ssdpc.simulation.sample_free",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    """Load a public name's module on first use (the package imports nothing heavy up front)."""
    if name in _EXPORTS:
        from importlib import import_module

        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
