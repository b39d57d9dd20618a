from .frame import RunReport, process_frame
from .job import Job
from .run import Pipeline
from .sinks import LatestSink, MemorySink, OmeTiffSink, OutputGrid, Sink, ZarrSink
from .sources import FrameSource, LiveFrames, as_source, grows

__all__ = [
    "FrameSource",
    "Job",
    "LatestSink",
    "LiveFrames",
    "MemorySink",
    "OmeTiffSink",
    "OutputGrid",
    "Pipeline",
    "RunReport",
    "Sink",
    "ZarrSink",
    "as_source",
    "grows",
    "process_frame",
]
