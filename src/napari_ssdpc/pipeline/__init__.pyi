from .job import Job
from .run import Pipeline, RunReport, process_frame
from .sinks import MemorySink, OmeTiffSink, OutputGrid, Sink, ZarrSink
from .sources import FrameSource, LiveFrames, StoredFrames, as_source

__all__ = [
    "FrameSource",
    "Job",
    "LiveFrames",
    "MemorySink",
    "OmeTiffSink",
    "OutputGrid",
    "Pipeline",
    "RunReport",
    "Sink",
    "StoredFrames",
    "ZarrSink",
    "as_source",
    "process_frame",
]
