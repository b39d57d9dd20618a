"""Validation: metrics, phantom cases, figures, the demo, the reference path and the benchmark.

Nothing here runs when a frame is reconstructed.
"""
