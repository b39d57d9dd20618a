from . import (
    layers,
    notify,
    objects_dock,
    placement,
    profiles,
    reader,
    sample_data,
    tracks,
    widgets,
    writer,
)

__all__ = [
    "layers",
    "notify",
    "objects_dock",
    "placement",
    "profiles",
    "reader",
    "sample_data",
    "tracks",
    "widgets",
    "writer",
]
