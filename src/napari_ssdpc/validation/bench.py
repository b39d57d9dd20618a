"""``ssdpc bench``: time the reconstruction of the standard case and compare it with the reference path.

The standard case (issue 5, docs/performance.md): the paper's optics at condenser NA 0.1, a
simulated 13 µm PMMA bead, z from −80 to +80 µm every 1 µm (161 planes), 10 Richardson–Lucy
iterations, the paper's route to phase (DPC stacks + Tikhonov, ``method='rl'``) and RI.

Everything is measured in one process on the same input; ratios, not absolute numbers, are
what carries over to another machine. Stages run in this order, and ``peak_rss_mb`` is the
process's peak resident memory at the end of each stage (it only grows): fast path at NA 0.1,
the default 'wotf' method, fast path at NA 0.3 (24 lit lenslets), the time series, then the
reference path. Simulated frames are cached (``cache_dir``) and simulated in a child process,
so that the simulator's memory does not count.
"""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np

from napari_ssdpc.reconstruction.methods import METHODS
from napari_ssdpc.settings.reconstruction import DEFAULT_Z_UM
from napari_ssdpc.validation.bench_stages import fast_path, peak_rss_mb, reference_stage, series_stage

STANDARD = {"z": DEFAULT_Z_UM, "dz": 1.0, "rl": {"iterations": 10}, "method": "rl"}
QUICK = {"z": DEFAULT_Z_UM, "dz": 16.0, "rl": {"iterations": 3}, "method": "rl"}
#: the regularised method's standard case: 121 planes at condenser NA 0.25 (16 lit lenslets)
TV_CASE = {"z": (-60.0, 60.0), "dz": 1.0, "rl": {"iterations": 10}, "method": "tv"}
TV_NA = 0.25
SENSOR_DZ = {False: 20.0, True: 80.0}  # planes of the sensor-canvas reference (it is slow)
SERIES_FRAMES = {False: 4, True: 3}
#: frames of the moving sample at NA 0.25: 'wotf', and 'tv' cold and warm-started
TV_SERIES_FRAMES = 8
TARGETS = {
    "speedup": 10.0,
    "peak_gb": 4.0,
    "max_rel_diff": 1e-3,
    "tv_frame_s": 10.0,
    "multislice_frame_s": 20.0,
    "multislice_warm_frame_s": 5.0,
    "tv_warm_frame_s": 2.0,
    "wotf_series_fps": 10.0,
}
#: the nonlinear method on the tv case's 13 µm bead, z -30..30 µm (its region: about 60 x 60 µm)
MULTISLICE_CASE = {**TV_CASE, "z": (-30.0, 30.0), "method": "multislice"}
#: where the bead of the series' next frame is, µm: a warm-started frame of 'multislice'
MOVED_UM = (1.0, 0.5, 0.5)


# ------------------------------------------------------------------- machine
def machine() -> dict:
    """What the benchmark ran on.

    Returns
    -------
    dict
        CPU, cores, memory (GB), Python, NumPy and SciPy versions, load average.
    """
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    mem = None
    try:
        mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError, AttributeError):
        pass
    import scipy

    return {
        "cpu": model,
        "cores": cores,
        "memory_gb": None if mem is None else round(mem, 1),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "load_average": _load(),
    }


def _load():
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


def _simulate(name, condenser_na, frames, cache_dir, center_um=(0.0, 0.0, 0.0)):
    from napari_ssdpc.settings.optics import Optics
    from napari_ssdpc.simulation import moving, phantoms
    from napari_ssdpc.validation.cases import simulate_case

    phantom = phantoms.pmma_bead(center_um) if frames is None else moving.moving_sample(frames)
    return simulate_case(name, phantom, Optics.paper().replace(condenser_na=condenser_na), cache_dir=cache_dir)


def simulated_case(name, condenser_na, cache_dir, frames=None, center_um=(0.0, 0.0, 0.0)):
    """A cached simulated case; simulated in a child process when it is not cached yet.

    Parameters
    ----------
    name : str
        Name of the case; the cache file is ``{name}_na{condenser_na}_s0.npz``.
    condenser_na : float
        Condenser NA of the paper's optics.
    cache_dir : Path
        Folder of the cached frames.
    frames : int, optional
        Frames of a moving-sample series; None: the PMMA bead, one frame.
    center_um : (float, float, float)
        Where the PMMA bead is, µm.

    Returns
    -------
    Case
    """
    path = Path(cache_dir) / f"{name}_na{condenser_na:g}_s0.npz"
    if not path.is_file():
        import multiprocessing as mp

        args = (name, condenser_na, frames, cache_dir, center_um)
        proc = mp.get_context("spawn").Process(target=_simulate, args=args)
        proc.start()
        proc.join()
        if proc.exitcode != 0:
            raise RuntimeError(f"simulating {name} failed (exit code {proc.exitcode})")
    return _simulate(name, condenser_na, frames, cache_dir, center_um)


def default_cache() -> Path:
    """Where simulated benchmark inputs are cached.

    Returns
    -------
    Path
        ``$XDG_CACHE_HOME/napari-ssdpc/bench`` (default ~/.cache).
    """
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "napari-ssdpc" / "bench"


# ------------------------------------------------------------------- stages
def run_bench(
    *,
    quick=False,
    device="cpu",
    cache_dir=None,
    reference=True,
    log=None,
    case=None,
    series_case=None,
    high_na_case=None,
) -> dict:
    """Run every stage and return the report (a JSON-able dict). ``case`` / ``series_case`` /
    ``high_na_case`` replace the simulated inputs (tests); ``high_na_case=False`` skips NA 0.3.

    Parameters
    ----------
    quick : bool
        Coarse z grid and few iterations (a smoke test).
    device : {'cpu', 'gpu'}
    cache_dir : Path, optional
    reference : bool
        Also run the slow reference path.
    log : callable, optional
        ``log(text)`` for progress lines.
    case, series_case, high_na_case : Case, optional
        Inputs instead of the simulated ones; ``high_na_case=False`` skips NA 0.3.

    Returns
    -------
    dict
        ``machine``, ``device``, ``quick``, ``case``, ``rss_before_mb``, ``stages`` and ``targets``.
    """
    from napari_ssdpc.backend import get_backend
    from napari_ssdpc.calibration import calibrate

    get_backend(device)  # a missing GPU stops here, before any work
    say = log or (lambda m: None)
    cache = Path(cache_dir) if cache_dir else default_cache()
    cfg = dict(QUICK if quick else STANDARD)
    report = {"machine": machine(), "device": device, "quick": bool(quick), "stages": {}}
    st = report["stages"]

    say("inputs: simulated PMMA bead, paper optics, condenser NA 0.1 (cached after the first run)")
    case = case or simulated_case("bench-pmma-bead", 0.1, cache)
    cal = calibrate(case.white, case.optics)
    frame = case.frame if case.frame.ndim == 2 else case.frame[0]
    report["case"] = {
        "condenser_na": case.optics.condenser_na,
        "medium_index": case.optics.medium_index,
        "frame_shape": list(frame.shape),
        **{k: list(v) if isinstance(v, tuple) else v for k, v in cfg.items()},
    }
    report["rss_before_mb"] = peak_rss_mb()

    say("fast path (standard case)")
    rec, res, st["fast"] = fast_path(case, cal, cfg, device)
    report["case"].update(
        planes=st["fast"]["planes"], lit_lenslets=st["fast"]["lit_lenslets"], view_shape=list(rec.mask.shape)
    )
    say(f"  build {st['fast']['build_s']:.1f} s, frame {st['fast']['frame_s']:.2f} s")

    for name, entry in METHODS.items():  # every registered method beside the standard case's
        if name == cfg["method"] or entry.slow:  # the slow ones run on their own case below
            continue
        say(f"method '{name}' ({entry.summary}), no RL stacks")
        _, m_res, st[name] = fast_path(case, cal, {**cfg, "method": name}, device, stacks=False)
        if "tv_iterations_run" in m_res.settings:
            _tv_iterations(st[name], m_res, say)

    if high_na_case is not False and not quick:
        say(f"'tv' on its standard case: 121 planes, condenser NA {TV_NA:g}, beside 'wotf' (Tikhonov)")
        tcase = simulated_case("bench-pmma-bead", TV_NA, cache)
        tcal = calibrate(tcase.white, tcase.optics)
        _, _, st["wotf_tv_case"] = fast_path(tcase, tcal, {**TV_CASE, "method": "wotf"}, device, stacks=False)
        _, tv_res, st["tv_case"] = fast_path(tcase, tcal, TV_CASE, device, stacks=False, repeats=1)
        _tv_iterations(st["tv_case"], tv_res, say)
        st.update(multislice_stages(tcase, tcal, device, cache, say))
        del tcase, tcal
        say(f"series at NA {TV_NA:g} ({TV_SERIES_FRAMES} frames of a moving sample): 'wotf', 'tv' cold and warm")
        mcase = simulated_case(f"bench-moving{TV_SERIES_FRAMES}", TV_NA, cache, frames=TV_SERIES_FRAMES)
        mcal = calibrate(mcase.white, mcase.optics)
        for key, method, warm in (
            ("series_wotf", "wotf", False),
            ("series_tv_cold", "tv", False),
            ("series_tv_warm", "tv", True),
        ):
            cfg_m = {**TV_CASE, "method": method}
            st[key] = series_stage(mcase, mcal, cfg_m, device, TV_SERIES_FRAMES, stacks=False, warm_start=warm)
            say(f"  {key}: {st[key]['steady_frames_per_s']:.2f} frames/s in steady state")
        del mcase, mcal

    if high_na_case is not False and not quick:
        say("fast path at condenser NA 0.3 (24 lit lenslets)")
        hcase = high_na_case or simulated_case("bench-pmma-bead", 0.3, cache)
        hcal = calibrate(hcase.white, hcase.optics)
        _, _, st["fast_na0.3"] = fast_path(hcase, hcal, cfg, device, repeats=1)
        del hcase, hcal

    say("time series (streamed from TIFF to OME-Zarr)")
    n = SERIES_FRAMES[bool(quick)]
    if series_case is None and not quick:
        series_case = simulated_case(f"bench-moving{n}", 0.1, cache, frames=n)
    if series_case is None:
        st["series"] = series_stage(case, cal, cfg, device, n, rec=rec)
    else:
        scal = calibrate(series_case.white, series_case.optics)
        st["series"] = series_stage(series_case, scal, cfg, device, n)

    if reference:
        say("reference path, canvas = the box of the spread EIs, all planes")
        st["reference_eis"] = reference_stage(rec, res, frame, "eis")
        say(f"  speed-up {st['reference_eis']['speedup']:.1f}x")
        say(f"reference path, canvas = the whole sensor, dz {SENSOR_DZ[bool(quick)]:g} µm")
        sub = {**cfg, "dz": SENSOR_DZ[bool(quick)]}
        rec_sub, res_sub, st["fast_sensor_planes"] = fast_path(case, cal, sub, device)
        del rec
        st["reference_sensor"] = reference_stage(rec_sub, res_sub, frame, "sensor", fast_full=st["fast"])
        say(f"  speed-up {st['reference_sensor']['speedup']:.1f}x at {st['reference_sensor']['planes']} planes")
    report["machine"]["load_average_end"] = _load()
    report["targets"] = _targets(report)
    return report


def multislice_stages(case, cal, device, cache, say) -> dict:
    """'multislice' on the PMMA bead (z −30..30 µm, in its region), then the series' next frame of
    the bead moved by :data:`MOVED_UM`, warm-started from the first.

    Parameters
    ----------
    case : Case
        The bead at condenser NA :data:`TV_NA`.
    cal : Calibration
    device : {'cpu', 'gpu'}
    cache : Path
        Folder of the simulated frames (the moved bead's is simulated there once).
    say : callable
        ``say(text)`` for progress lines.

    Returns
    -------
    dict
        ``multislice_case`` (as :func:`fast_path`, with the fit's iterations, region and a whole-field
        estimate) and ``multislice_warm`` (the warm frame's time, s, and the start it took).
    """
    say("'multislice' on the same bead, z -30..30 µm, in its region of interest")
    rec, res, cold = fast_path(case, cal, MULTISLICE_CASE, device, stacks=False, repeats=1)
    _multislice_iterations(cold, res, say)
    say(f"'multislice', the series' next frame (the bead moved by {MOVED_UM} µm), warm-started")
    moved = simulated_case("bench-pmma-bead-moved", TV_NA, cache, center_um=MOVED_UM).frame
    t0 = time.perf_counter()
    warm = rec.reconstruct(moved, warm=res.solution)
    out = {"frame_s": time.perf_counter() - t0, "start": warm.settings["multislice_start"]}
    say(f"  {out['frame_s']:.0f} s a frame (start: {out['start']})")
    return {"multislice_case": cold, "multislice_warm": out}


def _tv_iterations(stage: dict, result, say) -> None:
    """Add the TV solver's iteration count and time per iteration to a stage."""
    its = int(result.settings["tv_iterations_run"])
    stage.update(iterations=its, iteration_s=stage["phase_s"] / max(its, 1))
    say(f"  {its} iterations, {stage['iteration_s']:.2f} s each, {stage['frame_s']:.1f} s a frame")


def _multislice_iterations(stage: dict, result, say) -> None:
    """Add the nonlinear fit's iterations, time per iteration, region and a whole-field estimate."""
    s = result.settings
    its = int(s["multislice_iterations_run"])
    # the iterations' time: without the bead fit of the sphere start and the rest of the frame's 'tv'
    beside = float(s.get("multislice_sphere_start_seconds", 0.0)) + float(s.get("multislice_rest_seconds", 0.0))
    seconds = float(s["multislice_seconds"]) - beside
    r0, r1, c0, c1 = s["multislice_roi_px"]
    z0, z1 = s["multislice_z_um"]
    planes = int(round((z1 - z0) / result.voxel_um[0])) + 1
    ny, nx = result.delta_n.shape[1:]
    # a model iteration costs about (pixels) x (planes): the whole field and z range, scaled; none
    # when the start was kept as it is (no iteration ran)
    per = seconds / its if its else None
    whole = None if per is None else per * (ny * nx) / ((r1 - r0) * (c1 - c0)) * len(result.z_um) / planes
    stage.update(
        iterations=its,
        iteration_s=per,
        fit_s=seconds,
        roi_um=(r1 - r0) * result.voxel_um[1],
        model_planes=planes,
        source_points=s["multislice_source_points"],
        residual_over_noise=s["multislice_residual_over_noise"],
        whole_field_iteration_s=whole,
    )
    say(f"  {multislice_fit_words(stage)}, {stage['frame_s']:.0f} s a frame")


def multislice_fit_words(stage: dict) -> str:
    """The multislice fit of a bench stage in words: its iterations, their time, its region and the
    whole field's estimate, or that its start was kept as it is.

    Parameters
    ----------
    stage : dict
        ``iterations``, ``iteration_s`` (None: no iteration ran), ``roi_um``, ``model_planes``,
        ``whole_field_iteration_s``.

    Returns
    -------
    str
    """
    where = f"in {stage['roi_um']:.0f} µm x {stage['model_planes']} planes"
    if stage["iteration_s"] is None:
        return f"no iteration (its start kept as it is) {where}"
    return (
        f"{stage['iterations']} iterations of {stage['iteration_s']:.1f} s {where} "
        f"(the whole field: about {stage['whole_field_iteration_s']:.0f} s an iteration)"
    )


def _targets(report) -> dict:
    st = report["stages"]
    peak = max(s.get("peak_rss_mb", 0) for s in st.values()) / 1024
    out = {"peak_memory_gb": peak, "peak_memory_ok": peak < TARGETS["peak_gb"]}
    if "tv_case" in st:
        out.update(tv_frame_s=st["tv_case"]["frame_s"], tv_frame_ok=st["tv_case"]["frame_s"] <= TARGETS["tv_frame_s"])
    if "series_tv_warm" in st:
        f = 1.0 / st["series_tv_warm"]["steady_frames_per_s"]
        fps = st["series_wotf"]["steady_frames_per_s"]
        out.update(tv_warm_frame_s=f, tv_warm_frame_ok=f <= TARGETS["tv_warm_frame_s"])
        out.update(wotf_series_fps=fps, wotf_series_ok=fps >= TARGETS["wotf_series_fps"])
    if "multislice_case" in st:
        f = st["multislice_case"]["frame_s"]
        out.update(multislice_frame_s=f, multislice_frame_ok=f <= TARGETS["multislice_frame_s"])
    if "multislice_warm" in st:
        f = st["multislice_warm"]["frame_s"]
        out.update(multislice_warm_frame_s=f, multislice_warm_frame_ok=f <= TARGETS["multislice_warm_frame_s"])
    if "reference_sensor" in st:
        r = st["reference_sensor"]
        diffs = [
            st[k][d]
            for k in ("reference_eis", "reference_sensor")
            for d in ("max_rel_diff_stacks", "max_rel_diff_delta_n")
        ]
        out.update(
            speedup_sensor=r["speedup"],
            speedup_sensor_161=r.get("extrapolated_speedup"),
            speedup_eis=st["reference_eis"]["speedup"],
            speedup_ok=r["speedup"] >= TARGETS["speedup"],
            max_rel_diff=max(diffs),
            max_rel_diff_ok=max(diffs) <= TARGETS["max_rel_diff"],
        )
    return out
