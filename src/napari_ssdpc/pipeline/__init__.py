"""The frame loop: a job (configuration, calibration, flat), a frame source, a sink.

:class:`~.run.Pipeline` builds the job's Reconstructor once and streams the frames of any
:class:`~.sources.FrameSource` (a TIFF, an OME-Zarr image, an array, or frames still arriving) into any
:class:`~.sinks.Sink` (memory, OME-TIFF, a resumable OME-Zarr store), serially or on a Dask
cluster. The CLI, napari and the benchmark all run frames through it.
"""

import lazy_loader as _lazy

# The public names are listed in __init__.pyi; each module loads on first use.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
