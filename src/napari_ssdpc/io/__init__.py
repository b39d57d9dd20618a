"""Files: raw frames in, OME-TIFF and OME-Zarr out, and time series streamed to a resumable store."""

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "FrameSource": "napari_ssdpc.io.frame_source",
    "Recipe": "napari_ssdpc.io.series",
    "SeriesReport": "napari_ssdpc.io.series",
    "create_ome_zarr": "napari_ssdpc.io.frames",
    "read_frame": "napari_ssdpc.io.frames",
    "read_ome_zarr": "napari_ssdpc.io.frames",
    "reconstruct_series": "napari_ssdpc.io.series",
    "write_ome_tiff": "napari_ssdpc.io.frames",
    "write_ome_tiffs": "napari_ssdpc.io.frames",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    """Load a public name's module on first use (the package imports nothing heavy up front)."""
    if name in _EXPORTS:
        from importlib import import_module

        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
