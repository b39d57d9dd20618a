"""Validation: metrics, phantom cases, figures, the demo, the reference path and the benchmark.

Nothing here runs when a frame is reconstructed.
"""

# Submodules, imported where they are used (matplotlib and the simulator load only then).
__all__ = ["bench", "bench_report", "cases", "demo", "figures", "metrics", "reference"]
