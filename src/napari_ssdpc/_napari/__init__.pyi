from . import (
    layers,
    notify,
    placement,
    profiles,
    reader,
    sample_data,
    widgets,
    writer,
)

__all__ = [
    "layers",
    "notify",
    "placement",
    "profiles",
    "reader",
    "sample_data",
    "widgets",
    "writer",
]
