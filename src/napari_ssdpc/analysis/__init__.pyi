from .objects import ObjectRule, measure_objects, noise_sigma, segment
from .result_files import StoredResult, open_result
from .table import measure_result, measure_series, read_csv, write_csv
from .tracks import link_tracks

__all__ = [
    "ObjectRule",
    "StoredResult",
    "link_tracks",
    "measure_objects",
    "measure_result",
    "measure_series",
    "noise_sigma",
    "open_result",
    "read_csv",
    "segment",
    "write_csv",
]
