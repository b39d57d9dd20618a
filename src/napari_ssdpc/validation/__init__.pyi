from . import (
    bench,
    bench_report,
    cases,
    demo,
    figures,
    metrics,
    reference,
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
    "truth",
]
