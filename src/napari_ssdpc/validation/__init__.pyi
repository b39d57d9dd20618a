from . import (
    bench,
    bench_report,
    cases,
    demo,
    figures,
    metrics,
    reference,
    reference_layout,
    truth,
)

__all__ = [
    "bench",
    "bench_report",
    "cases",
    "demo",
    "figures",
    "metrics",
    "reference",
    "reference_layout",
    "truth",
]
