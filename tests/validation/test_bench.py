"""Benchmark machinery: the reference path computes what the fast path computes; the report.

No test here times anything (benchmarks print ratios)."""

import json

import numpy as np
import pytest

from napari_ssdpc.cli.main import main
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.validation.bench import run_bench
from napari_ssdpc.validation.bench_report import format_report
from napari_ssdpc.validation.cases import Case, run_config
from napari_ssdpc.validation.reference import max_relative_difference, reconstruct_reference
from napari_ssdpc.validation.reference_layout import layout


@pytest.fixture(scope="module")
def data(synthetic_series):
    return synthetic_series


def _check_equal(rec, frame, canvas):
    fast = rec.reconstruct(frame)
    ref = reconstruct_reference(rec, frame, canvas=canvas)
    for h, stack in fast.stacks.items():
        assert np.ptp(stack) > 0.05 * np.abs(stack).max()  # a real image, not a constant
        assert max_relative_difference(stack, ref.stacks[h]) < 1e-3
    assert max_relative_difference(fast.delta_n, ref.delta_n) < 1e-3
    return ref


def test_reference_path_equals_fast_path_on_the_ei_box(data):
    optics, cal, flat, frames, _ = data
    rec = Reconstructor(run_config(optics, z=(-40, 40), dz=10, rl={"iterations": 4}, method="rl"), cal, flat=flat)
    ref = _check_equal(rec, frames[0], "eis")
    assert ref.layout.area_ratio > 4  # four 2x2-spread windows and their margins


def test_reference_path_on_the_whole_sensor(data):
    optics, cal, flat, frames, _ = data
    rec = Reconstructor(run_config(optics, z=(-20, 20), dz=20, rl={"iterations": 2}, method="rl"), cal, flat=flat)
    ref = _check_equal(rec, frames[1], "sensor")
    assert ref.layout.shape == tuple(cal.frame_shape)


def test_spread_layout_keeps_every_kernel_and_separates_the_eis(data):
    optics, cal, flat, _, _ = data
    rec = Reconstructor(run_config(optics, z=(-80, 80), dz=40, rl={"iterations": 1}, method="rl"), cal, flat=flat)
    psf = rec.stacks.psf
    lay = layout(rec, "eis")
    shift = np.abs(psf.tilt).max() * 80 / rec.pixel_um
    assert min(lay.reach) >= psf.support_px // 2 + shift  # the crop keeps the kernel support
    # light of one lenslet, from anywhere in the object domain, never reaches another lenslet's view
    import scipy.fft as sfft

    from napari_ssdpc.validation.reference_layout import full_frame_psf, lenslet_kernels

    kernels = np.abs(lenslet_kernels(rec, 80.0, lay))
    ones = np.ones(lay.fft_shape, np.float32)
    for k in range(len(rec.lenslets)):
        psf = full_frame_psf(kernels, [k], lay)
        img = sfft.irfft2(sfft.rfft2(ones, s=lay.shape) * sfft.rfft2(psf), s=lay.shape)
        assert img[lay.windows(k)].min() > 0.5 * img.max()
        for other in range(len(rec.lenslets)):
            if other != k:
                assert np.abs(img[lay.windows(other)]).max() < 1e-5 * img.max()
    obj = np.random.default_rng(0).random((2,) + lay.fft_shape)
    np.testing.assert_array_equal(lay.to_circular(lay.to_linear(obj)), obj)


def test_quick_bench_report(data):
    optics, cal, flat, frames, white = data
    case = Case("synthetic", optics, None, frames[0], flat, white, None)
    report = run_bench(quick=True, case=case, reference=False, high_na_case=False)
    st = report["stages"]
    assert set(st) == {"fast", "wotf", "tv", "series"}
    assert report["case"]["planes"] == 11 and report["case"]["rl"]["iterations"] == 3
    assert st["fast"]["lit_lenslets"] == 4 and 0 < st["fast"]["band_fraction"] < 0.3
    assert st["series"]["frames"] == 3
    assert report["machine"]["cores"] >= 1 and report["targets"]["peak_memory_gb"] > 0
    json.dumps(report)  # JSON-able for --json
    text = format_report(report)
    assert "| fast, NA 0.1 (standard) | 11 | 4 |" in text and "serial, OME-Zarr" in text
    assert "| fast, method tv, NA 0.1 | 11 | 4 |" in text and report["stages"]["tv"]["iterations"] >= 1


@pytest.mark.slow
def test_cli_bench_quick_json(tmp_path, capsys):
    """`ssdpc bench --quick --json` end to end (simulates the PMMA bead once, about a minute)."""
    assert main(["bench", "--quick", "--json", "--cache", str(tmp_path)]) == 0
    report = json.loads(capsys.readouterr().out)
    t = report["targets"]
    assert t["max_rel_diff"] < 1e-3 and t["peak_memory_ok"]
    assert report["stages"]["reference_sensor"]["canvas"] == [2048, 2448]


def test_series_rows_of_the_warm_started_method(data):
    """The bench's tv series rows: every frame written, the warm-started run reports the same
    streamed frames, and the report's series table names each row."""
    from napari_ssdpc.validation.bench_stages import series_stage

    optics, cal, flat, frames, white = data
    case = Case("synthetic", optics, None, frames[:3], flat, white, None)
    cfg = {"z": (-20.0, 20.0), "dz": 10.0, "method": "tv", "tv": {"iterations": 6, "warm_iterations": 2}}
    rows = {warm: series_stage(case, cal, cfg, "cpu", 3, stacks=False, warm_start=warm) for warm in (False, True)}
    for row in rows.values():
        assert row["frames"] == 3 and row["steady_frames_per_s"] > 0 and row["reconstruct_s"] > 0
    report = {
        "machine": {
            "cpu": "x",
            "cores": 2,
            "memory_gb": 1,
            "python": "3",
            "numpy": "2",
            "scipy": "1",
            "load_average": 0,
        },
        "case": {"condenser_na": 0.25, "z": [-20, 20], "dz": 10, "planes": 5, "rl": {"iterations": 1}},
        "device": "cpu",
        "quick": True,
        "stages": {"series_tv_cold": rows[False], "series_tv_warm": rows[True], "series_wotf": rows[False]},
    }
    report["case"].update(method="tv", lit_lenslets=4, view_shape=[145, 145])
    from napari_ssdpc.validation.bench import _targets

    report["targets"] = _targets(report)
    text = format_report(report)
    assert "tv warm-started, NA 0.25, moving sample" in text and "tv warm-started" in text.splitlines()[-1]


def test_a_kept_start_reports_no_iteration_time():
    """A multislice frame whose start was kept ran no iteration: no time per iteration (nor a whole
    field's estimate from it) is made up from the frame's other work."""
    from napari_ssdpc.validation.bench import multislice_fit_words

    stage = {"iterations": 0, "iteration_s": None, "roi_um": 37.2, "model_planes": 61, "whole_field_iteration_s": None}
    assert multislice_fit_words(stage) == "no iteration (its start kept as it is) in 37 µm x 61 planes"
    stage |= {"iterations": 3, "iteration_s": 2.5, "whole_field_iteration_s": 120.0}
    words = multislice_fit_words(stage)
    assert words.startswith("3 iterations of 2.5 s in 37 µm x 61 planes (the whole field: about 120 s")
