"""The ``ssdpc bench`` report as Markdown tables: machine, case, stages, targets."""

from __future__ import annotations

import math

from napari_ssdpc.reconstruction.methods import METHODS
from napari_ssdpc.validation.bench import TV_NA, multislice_fit_words

__all__ = ["format_report"]


def _row(cells):
    return "| " + " | ".join(str(c) for c in cells) + " |"


def _table(head, rows):
    return "\n".join([_row(head), _row(["---"] * len(head))] + [_row(r) for r in rows])


def _f(v, nd=2):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    return f"{v:.{nd}f}"


def format_report(report) -> str:
    """The benchmark report as Markdown tables.

    Parameters
    ----------
    report : dict
        As :func:`~napari_ssdpc.validation.bench.run_bench` returns it.

    Returns
    -------
    str
        Markdown.
    """
    m, c, st = report["machine"], report["case"], report["stages"]
    lines = [
        f"machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB; Python {m['python']}, "
        f"NumPy {m['numpy']}, SciPy {m['scipy']}; device {report['device']}; "
        f"load average {m['load_average']} -> {m.get('load_average_end')}",
        f"case: PMMA bead, condenser NA {c['condenser_na']:g}, z {c['z'][0]:g}..{c['z'][1]:g} µm every "
        f"{c['dz']:g} µm ({c['planes']} planes), {c['rl']['iterations']} RL iterations, method {c['method']}, "
        f"{c['lit_lenslets']} lit lenslets, views {c['view_shape']}" + (" (QUICK)" if report["quick"] else ""),
        "",
    ]
    rows = []
    for key, label in (
        ("fast", "fast, NA 0.1 (standard)"),
        *((name, f"fast, method {name}, NA 0.1") for name in METHODS if not METHODS[name].slow),
        ("wotf_tv_case", f"method wotf, NA {TV_NA:g}"),
        ("tv_case", f"method tv, NA {TV_NA:g}"),
        ("multislice_case", f"method multislice, NA {TV_NA:g}, z -30..30"),
        ("fast_na0.3", "fast, NA 0.3"),
        ("fast_sensor_planes", "fast, fewer planes"),
    ):
        if key in st:
            s = st[key]
            rows.append(
                [
                    label,
                    s["planes"],
                    s["lit_lenslets"],
                    _f(s["build_s"], 1),
                    _f(s["first_frame_s"]),
                    _f(s["frame_s"]),
                    _f(s["preprocess_s"]),
                    _f(s["rl_s"]),
                    _f(s.get("dpc_s", 0.0)),
                    _f(s["phase_s"]),
                    _f(s["peak_rss_mb"] / 1024),
                ]
            )
    lines.append(
        _table(
            [
                "path",
                "planes",
                "lenslets",
                "build s",
                "1st frame s",
                "frame s",
                "views s",
                "RL s",
                "DPC s",
                "phase+RI s",
                "peak RSS GB",
            ],
            rows,
        )
    )
    series = [
        (key, label)
        for key, label in (
            ("series", "serial, OME-Zarr, standard case"),
            ("series_wotf", f"wotf, NA {TV_NA:g}, moving sample"),
            ("series_tv_cold", f"tv cold, NA {TV_NA:g}, moving sample"),
            ("series_tv_warm", f"tv warm-started, NA {TV_NA:g}, moving sample"),
        )
        if key in st
    ]
    if series:
        lines += [
            "",
            _table(
                [
                    "series",
                    "frames",
                    "build s",
                    "frames/s (all)",
                    "frames/s (steady)",
                    "read s/frame",
                    "reconstruct s/frame",
                    "write s/frame",
                    "peak RSS GB",
                ],
                [
                    [
                        label,
                        st[key]["frames"],
                        _f(st[key]["build_s"], 1),
                        _f(st[key]["frames_per_s"], 3),
                        _f(st[key]["steady_frames_per_s"], 3),
                        _f(st[key]["read_s"], 3),
                        _f(st[key]["reconstruct_s"]),
                        _f(st[key]["write_s"], 3),
                        _f(st[key]["peak_rss_mb"] / 1024),
                    ]
                    for key, label in series
                ],
            ),
        ]
    rows = []
    for key, label in (("reference_eis", "EI box"), ("reference_sensor", "whole sensor")):
        if key in st:
            s = st[key]
            rows.append(
                [
                    label,
                    "x".join(map(str, s["canvas"])),
                    _f(s["canvas_vs_view_grid"], 1),
                    s["planes"],
                    _f(s["build_s"], 1),
                    _f(s["frame_s"]),
                    _f(s["fast_frame_s"]),
                    _f(s["speedup"], 1) + "x",
                    f"{s['max_rel_diff_stacks']:.1e}",
                    f"{s['max_rel_diff_delta_n']:.1e}",
                ]
            )
            if "extrapolated_frame_s" in s:
                rows.append(
                    [
                        label + f", scaled to {s['extrapolated_planes']} planes",
                        "",
                        "",
                        s["extrapolated_planes"],
                        "",
                        _f(s["extrapolated_frame_s"], 1),
                        _f(st["fast"]["frame_s"]),
                        _f(s["extrapolated_speedup"], 1) + "x",
                        "",
                        "",
                    ]
                )
    if rows:
        lines += [
            "",
            _table(
                [
                    "reference canvas",
                    "canvas px",
                    "canvas / view grid",
                    "planes",
                    "PSF build s",
                    "ref frame s",
                    "fast frame s",
                    "speed-up",
                    "max rel diff stacks",
                    "max rel diff Δn",
                ],
                rows,
            ),
        ]
    t = report["targets"]
    lines += ["", f"targets: peak memory {t['peak_memory_gb']:.2f} GB (< 4: {t['peak_memory_ok']})"]
    if "speedup_ok" in t:
        lines[-1] += (
            f"; speed-up vs whole-sensor reference {t['speedup_sensor']:.1f}x (>= 10: {t['speedup_ok']}); "
            f"max rel diff {t['max_rel_diff']:.1e} (<= 1e-3: {t['max_rel_diff_ok']})"
        )
    if "tv_frame_ok" in t:
        its = st["tv_case"]
        lines[-1] += (
            f"; tv {t['tv_frame_s']:.1f} s a frame at NA {TV_NA:g} (<= 10: {t['tv_frame_ok']}), "
            f"{its['iterations']} iterations of {its['iteration_s']:.2f} s"
        )
    if "tv_warm_frame_ok" in t:
        lines[-1] += (
            f"; tv warm-started {t['tv_warm_frame_s']:.2f} s a frame (<= 2: {t['tv_warm_frame_ok']}); "
            f"wotf series {t['wotf_series_fps']:.1f} frames/s (>= 10: {t['wotf_series_ok']})"
        )
    if "multislice_frame_ok" in t:
        ms = st["multislice_case"]
        lines[-1] += (
            f"; multislice {t['multislice_frame_s']:.0f} s a frame (<= 20: {t['multislice_frame_ok']}), "
            f"{multislice_fit_words(ms)}, residual {ms['residual_over_noise']:.1f} x the noise"
        )
    if "multislice_warm_frame_ok" in t:
        lines[-1] += (
            f"; multislice warm-started {t['multislice_warm_frame_s']:.0f} s a frame "
            f"(<= 5: {t['multislice_warm_frame_ok']}; start: {st['multislice_warm']['start']})"
        )
    return "\n".join(lines)
