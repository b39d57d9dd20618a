from .followed import FollowedFrames
from .frame_source import StoredFrames
from .frames import read_frame, write_ome_tiff, write_ome_tiffs
from .ome_zarr import create_ome_zarr, read_ome_zarr
from .store import done_frames, open_store, read_complete, write_frame

__all__ = [
    "FollowedFrames",
    "StoredFrames",
    "create_ome_zarr",
    "done_frames",
    "open_store",
    "read_complete",
    "read_frame",
    "read_ome_zarr",
    "write_frame",
    "write_ome_tiff",
    "write_ome_tiffs",
]
