"""The stages of the benchmark: one method's fast path, a streamed series, the reference path.

Each returns its timings (s) and the peak resident memory (MB); :func:`napari_ssdpc.validation.bench.run_bench`
runs them and :mod:`.bench_report` formats what they return.
"""

from __future__ import annotations

import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["fast_path", "peak_rss_mb", "reference_stage", "series_stage"]


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far (MB).

    Returns
    -------
    float
        MB (2**20 bytes).
    """
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / 1024 if sys.platform != "darwin" else r / 2**20


# -------------------------------------------------------------------- inputs


def _frame_times(rec, frame, repeats=2) -> dict:
    """Reconstruct ``repeats`` times; the first frame (FFT plans, caches) and the last one."""
    first = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = rec.reconstruct(frame)
        wall = time.perf_counter() - t0
        first = wall if first is None else first
    return {"first_frame_s": first, "frame_s": wall, **{k: v for k, v in res.timings.items()}}, res


def fast_path(case, cal, cfg, device="cpu", stacks=True, repeats=2):
    """Build the operators and time frames of the fast path.

    Parameters
    ----------
    case : Case
    cal : Calibration
    cfg : dict
        z range, dz and reconstruction keys (see :func:`~napari_ssdpc.validation.cases.run_config`).
    device : {'cpu', 'gpu'}
    stacks : bool
        Build the Richardson-Lucy operators too.
    repeats : int
        Frames reconstructed; the first and the last are reported.

    Returns
    -------
    rec : Reconstructor
    result : Result
        The last frame's.
    info : dict
        Build, first-frame and frame times and the stage timings (s), lit lenslets, planes,
        peak RSS (MB).
    """
    from napari_ssdpc.reconstruction.reconstructor import Reconstructor
    from napari_ssdpc.validation.cases import run_config

    t0 = time.perf_counter()
    rec = Reconstructor(run_config(case.optics, device=device, **cfg), cal, flat=case.flat, stacks=stacks)
    build = time.perf_counter() - t0
    frame = case.frame if case.frame.ndim == 2 else case.frame[0]
    times, res = _frame_times(rec, frame, repeats)
    info = {
        "build_s": build,
        **times,
        "lit_lenslets": len(rec.lit),
        "planes": len(rec.z_um),
        "peak_rss_mb": peak_rss_mb(),
    }
    if rec.stacks is not None:
        info.update(fft_shape=list(rec.stacks.fft_shape), band_fraction=rec.stacks.band.fraction)
    return rec, res, info


def series_stage(case, cal, cfg, device, n_frames, rec=None, *, stacks=True, warm_start=False) -> dict:
    """Stream a TIFF series through ``ssdpc reconstruct``'s code (serial) into OME-Zarr.

    Parameters
    ----------
    case : Case
    cal : Calibration
    cfg : dict
        Reconstructor keywords.
    device : {'cpu', 'gpu'}
    n_frames : int
        Length of the series when ``case`` has a single frame (repeated).
    rec : Reconstructor, optional
        Reused when given.
    stacks : bool
        Compute the directional stacks of every frame (the 'rl' standard case).
    warm_start : bool
        Start every frame where the previous frame's solve ended.

    Returns
    -------
    dict
        Frames, build time (s), frames per second (all and steady), mean read, reconstruct and
        write times per frame (s), peak RSS (MB).
    """
    import tifffile

    from napari_ssdpc.pipeline.job import Job
    from napari_ssdpc.pipeline.run import Pipeline
    from napari_ssdpc.pipeline.sinks import ZarrSink
    from napari_ssdpc.validation.cases import run_config

    frames = case.frame if case.frame.ndim == 3 else np.stack([case.frame] * n_frames)
    job = Job(run_config(case.optics, device=device, **cfg), cal, case.flat, stacks=stacks)
    with tempfile.TemporaryDirectory(prefix="ssdpc-bench-") as tmp:
        src = Path(tmp) / "series.tif"
        tifffile.imwrite(src, frames, photometric="minisblack")
        t0 = time.perf_counter()
        pipeline = Pipeline(job, reconstructor=rec)
        build = time.perf_counter() - t0
        rep = pipeline.run(src, ZarrSink(Path(tmp) / "out.zarr"), progress=False, warm_start=warm_start)
    steady = rep.timings[1:] or rep.timings  # the first frame pays for the FFT plans (and starts cold)
    mean = {k: float(np.mean([t[k] for t in steady])) for k in ("read_s", "reconstruct_s", "write_s")}
    first = rep.timings[0]
    # from the first frame reconstructed to the last one written (each write runs beside the next
    # frame's reconstruction, so the parts' sum would overstate a frame's time)
    wall = rep.seconds - first["read_s"] - first["reconstruct_s"] if len(rep.timings) > 1 else rep.seconds
    return {
        "frames": rep.frames,
        "build_s": build,
        "seconds": rep.seconds,
        "frames_per_s": rep.frames_per_second,
        "steady_frames_per_s": len(steady) / wall,
        **mean,
        "peak_rss_mb": peak_rss_mb(),
    }


def reference_stage(rec, res_fast, frame, canvas, fast_full=None) -> dict:
    """The reference path on the Reconstructor's own z grid; speed-up and largest differences.

    Parameters
    ----------
    rec : Reconstructor
        Built with the Richardson-Lucy operators.
    res_fast : Result
        The fast path's result of ``frame``.
    frame : ndarray, (H, W)
        Raw frame.
    canvas : {'sensor', 'eis'}
        The reference path's canvas (see :func:`~napari_ssdpc.validation.reference_layout.layout`).
    fast_full : dict, optional
        The fast path's stage info (from :func:`fast_path`) on the full z grid: the reference's
        frame time is extrapolated to its number of planes.

    Returns
    -------
    dict
        Canvas shape (px), build and frame times (s), speed-up, largest relative differences of
        the stacks and of Δn, peak RSS (MB).
    """
    from napari_ssdpc.validation.reference import max_relative_difference, reconstruct_reference

    ref = reconstruct_reference(rec, frame, canvas=canvas)
    # the fast path's rl_s holds its DPC too (the directional stacks are one stage)
    per_frame = sum(ref.timings.get(k, 0.0) for k in ("preprocess_s", "rl_s", "dpc_s", "phase_s"))
    fast = sum(res_fast.timings.get(k, 0.0) for k in ("preprocess_s", "rl_s", "dpc_s", "phase_s"))
    out = {
        "canvas": list(ref.layout.shape),
        "canvas_vs_view_grid": ref.layout.area_ratio,
        "planes": len(rec.z_um),
        "build_s": ref.timings["build_s"],
        "rl_s": ref.timings["rl_s"],
        "frame_s": per_frame,
        "fast_frame_s": fast,
        "speedup": per_frame / fast,
        "max_rel_diff_stacks": max(max_relative_difference(res_fast.stacks[h], ref.stacks[h]) for h in ref.stacks),
        "max_rel_diff_delta_n": max_relative_difference(res_fast.delta_n, ref.delta_n),
        "peak_rss_mb": peak_rss_mb(),
    }
    if fast_full is not None:
        # whole-sensor FFTs per plane: 2Z + 2 per iteration and half; scale the measured RL time
        z, zf = len(rec.z_um), fast_full["planes"]
        rl_full = ref.timings["rl_s"] * (2 * zf + 2) / (2 * z + 2)
        full = per_frame - ref.timings["rl_s"] + rl_full
        fast_f = sum(fast_full.get(k, 0.0) for k in ("preprocess_s", "rl_s", "dpc_s", "phase_s"))
        out.update(extrapolated_planes=zf, extrapolated_frame_s=full, extrapolated_speedup=full / fast_f)
    return out


# --------------------------------------------------------------------- driver
