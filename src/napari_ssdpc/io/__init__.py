"""Files: raw frames in, OME-TIFF and OME-Zarr out, and time series streamed to a resumable store."""

from napari_ssdpc.io.frame_source import FrameSource
from napari_ssdpc.io.frames import create_ome_zarr, read_frame, read_ome_zarr, write_ome_tiff, write_ome_tiffs
from napari_ssdpc.io.series import Recipe, SeriesReport, reconstruct_series

__all__ = [
    "FrameSource",
    "Recipe",
    "SeriesReport",
    "create_ome_zarr",
    "read_frame",
    "read_ome_zarr",
    "reconstruct_series",
    "write_ome_tiff",
    "write_ome_tiffs",
]
