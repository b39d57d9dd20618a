"""The bad-input and fault sweep of issue 11, class by class, through the CLI and the API.

Every refused run exits 2 with one line (``cli`` fixture), and the ``sums`` fixture checks the
SHA-256 of every input file after each test: nothing is lost.
"""

import errno
import hashlib
import importlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import tifffile

from napari_ssdpc.cli.main import build_parser
from napari_ssdpc.reconstruction import checks, memory
from napari_ssdpc.settings.optics import Optics

PAPER = json.dumps({k: v for k, v in Optics.paper().to_dict().items() if k != "flip_x"}) + "\n"


def sha(p):
    return hashlib.sha256(p.read_bytes()).hexdigest()


# ---------------------------------------------------------------- 1, 2: data lost
@pytest.mark.parametrize("target", ["raw.tif", "flat.tif", "./raw.tif", "link.tif", "cal.json"])
def test_1_an_output_never_replaces_an_input(files, sums, cli, rec_args, monkeypatch, target):
    monkeypatch.chdir(files)
    rc, err = cli(rec_args(target))
    assert rc == 2 and "would overwrite the" in err and "write the output to another path" in err


def test_1_calibrate_never_replaces_the_white_frame(files, sums, cli):
    rc, err = cli(["calibrate", files / "white.tif", "-o", files / "white.tif"])
    assert rc == 2 and "would overwrite the white frame" in err


def test_2_the_overlay_never_replaces_the_calibration_or_a_foreign_png(files, sums, cli, tmp_path):
    rc, err = cli(["calibrate", files / "white.tif", "-o", tmp_path / "cal.png"])
    assert rc == 2 and "overlay would be written over the calibration" in err and "cal.json" in err
    mine = tmp_path / "mycal.png"
    mine.write_bytes(b"a holiday photo")
    rc, err = cli(["calibrate", files / "white.tif", "-o", tmp_path / "mycal.json"])
    assert rc == 2 and "--overwrite" in err and mine.read_bytes() == b"a holiday photo"
    assert not (tmp_path / "mycal.json").exists()
    assert cli(["calibrate", files / "white.tif", "-o", tmp_path / "mycal.json", "--overwrite"])[0] == 0
    assert json.loads((tmp_path / "mycal.json").read_text())["format"].startswith("napari-ssdpc")
    assert mine.read_bytes()[:4] == b"\x89PNG"
    # a rerun replaces its own pair without --overwrite
    assert cli(["calibrate", files / "white.tif", "-o", tmp_path / "mycal.json"])[0] == 0


def test_2_4_extra_outputs_are_guarded_and_written_as_one_set(files, sums, cli, rec_args, tmp_path, monkeypatch):
    out, phase = tmp_path / "out.ome.tif", tmp_path / "out_phase.ome.tif"
    phase.write_bytes(b"someone else's phase")
    rc, err = cli(rec_args(out, "--save", "phase"))
    assert rc == 2 and "did not write" in err and not out.exists()
    phase.unlink()
    assert cli(rec_args(out, "--save", "phase"))[0] == 0
    before = {p: sha(p) for p in (out, phase)}
    real, calls = tifffile.imwrite, {"n": 0}

    def imwrite(*a, **k):  # the disk fills up on the second file of the set
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(*a, **k)

    monkeypatch.setattr(tifffile, "imwrite", imwrite)
    rc, err = cli(rec_args(out, "--save", "phase", "--dz", "2"))
    assert rc == 2 and "no space left on the device" in err
    assert {p: sha(p) for p in (out, phase)} == before and not list(tmp_path.glob(".*.part"))
    monkeypatch.undo()
    assert cli(rec_args(out, "--save", "phase", "--dz", "2"))[0] == 0  # a file of ours: replaced
    with tifffile.TiffFile(out) as tif:
        assert 'PhysicalSizeZ="2.0"' in tif.ome_metadata  # item 14: a single plane keeps its dz


def test_the_configs_outputs_are_written_beside_a_single_frame(files, sums, cli, rec_args, tmp_path):
    """`outputs: save: [...]` of a run configuration writes one file per quantity (as --save does),
    and --save replaces the config's list."""
    cfg = tmp_path / "run.yaml"
    cfg.write_text("outputs:\n  save: [opd_nm, phase]\n")
    out = tmp_path / "out.ome.tif"
    rc, err = cli(rec_args(out, "--config", cfg))
    assert rc == 0, err
    written = sorted(p.name for p in tmp_path.glob("out*.ome.tif"))
    assert written == ["out.ome.tif", "out_opd_nm.ome.tif", "out_phase.ome.tif"]
    with tifffile.TiffFile(tmp_path / "out_opd_nm.ome.tif") as tif:
        assert np.abs(tif.asarray()).max() > 0
    other = tmp_path / "other.ome.tif"
    assert cli(rec_args(other, "--config", cfg, "--save", "phase"))[0] == 0
    assert sorted(p.name for p in tmp_path.glob("other*.ome.tif")) == ["other.ome.tif", "other_phase.ome.tif"]


# ------------------------------------------------------- 5, 6: nonsense written
def _bad_frames(flat):
    top = 4095
    rng = np.random.default_rng(1)
    return {
        "zero": (np.zeros_like(flat), "every pixel is 0"),
        "saturated": (np.full_like(flat, top), "camera was saturated"),
        "noise": (rng.integers(0, top + 1, flat.shape).astype(flat.dtype), "no light in the directly lit"),
        "negated": ((top - flat).astype(flat.dtype), "no light in the directly lit"),
    }


@pytest.mark.parametrize("kind", ["zero", "saturated", "noise", "negated"])
def test_5_frames_without_light_are_refused(synthetic_series, files, sums, cli, rec_args, tmp_path, kind):
    frame, words = _bad_frames(synthetic_series[2])[kind]
    bad = tmp_path / f"{kind}.tif"
    tifffile.imwrite(bad, frame)
    args = rec_args(tmp_path / "out.ome.tif")
    args[1] = bad
    rc, err = cli(args)
    assert rc == 2 and words in err and not (tmp_path / "out.ome.tif").exists()


def test_5_a_white_frame_given_as_the_raw_frame_is_refused(files, sums, cli, rec_args, tmp_path):
    args = rec_args(tmp_path / "out.ome.tif")
    args[1] = files / "white.tif"
    rc, err = cli(args)
    assert rc == 2 and "as on a white frame" in err and "not the white frame" in err
    assert not (tmp_path / "out.ome.tif").exists()


def test_5_blank_and_white_flats_are_refused(synthetic_series, files, sums, cli, rec_args, tmp_path):
    optics, cal, flat, _, white = synthetic_series
    blank = tmp_path / "blank.tif"
    tifffile.imwrite(blank, np.full_like(flat, 100))
    for f, words in ((blank, "every pixel is 100"), (files / "white.tif", "as on a white frame")):
        args = rec_args(tmp_path / "o.ome.tif")
        args[args.index("--flat") + 1] = f
        rc, err = cli(args)
        assert rc == 2 and words in err and "dark-field" not in err


def test_6_non_finite_and_unphysical_volumes_are_refused(synthetic_series, cli, rec_args, tmp_path):
    optics = synthetic_series[0]
    with pytest.raises(checks.SsdpcError, match="3 NaN/inf values; nothing was written"):
        checks.check_result(np.array([0.0, np.nan, np.inf, -np.inf]), optics)
    with pytest.raises(checks.SsdpcError, match=r"\|Δn\| = 9e\+12.*condenser NA"):
        checks.check_result(np.array([0.01, -9e12]), optics)
    checks.check_result(np.array([0.01, -0.02]), optics)
    for flag in (["--dz", "inf"], ["--alpha", "inf"], ["--dz", "nan"], ["--alpha", "-1"]):
        rc, err = cli(rec_args(tmp_path / "o.ome.tif", *flag))
        assert rc == 2 and not (tmp_path / "o.ome.tif").exists(), flag


def test_7_a_calibration_for_other_optics_or_edited_is_refused(synthetic_series, files, sums, cli, rec_args, tmp_path):
    optics = synthetic_series[0]
    d = optics.to_dict()
    d["objective"]["magnification"] = 40.0
    other = tmp_path / "40x.yaml"
    other.write_text(json.dumps(d))
    rc, err = cli(rec_args(tmp_path / "o.ome.tif", "--optics", other))
    assert rc == 2 and "objective magnification (objective.magnification: 40x vs 20x in the calibration)" in err
    cal = json.loads((files / "cal.json").read_text())
    cal["grid"]["pitch_px"] *= 1.1
    cal["pitch_px"] *= 1.1
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(cal))
    args = rec_args(tmp_path / "o.ome.tif")
    args[args.index("--calibration") + 1] = edited
    rc, err = cli(args)
    assert rc == 2 and ("lattice pitch" in err or "calibration" in err)


@pytest.mark.parametrize(
    "text, words",
    [
        ("optics: {flip_x: 'false', " + PAPER[1:], "flip_x"),
        ("reconstruction: {dz_um: 1}\nreconstruction: {dz_um: 2}\n", "given twice"),
        ("reconstruction: {dz_um: abc}\n", "dz_um"),
        ("reconstruction: {rl_iterations: null}\n", "rl.iterations"),
        ("reconstruction: {rl: {iterations: null}}\n", "rl.iterations"),
        ("reconstruction: {}\noutputs: {save: [magic]}\n", "unknown output"),
        ("a: " + "[" * 3000 + "]" * 3000 + "\n", "nested too deeply"),
    ],
)
def test_8_11_settings_files_are_strict(files, sums, cli, rec_args, tmp_path, text, words):
    cfg = tmp_path / "run.yaml"
    cfg.write_text(text)
    rc, err = cli(rec_args(tmp_path / "o.ome.tif", "--config", cfg))
    assert rc == 2 and words in err


def test_11_a_settings_file_that_is_not_utf8(files, cli, rec_args, tmp_path):
    cfg = tmp_path / "run.yaml"
    cfg.write_bytes(b"reconstruction: {dz_um: \xff\xfe}\n")
    rc, err = cli(rec_args(tmp_path / "o.ome.tif", "--config", cfg))
    assert rc == 2 and "UTF-8" in err


# --------------------------------------------------------------- 9-12: tracebacks
def test_9_impossible_sizes_are_refused_before_allocating(files, sums, cli, rec_args, tmp_path, monkeypatch):
    for flags, words in (
        (["--z", "-1000000", "1000000"], "z_min_um"),
        (["--z", "-80", "80", "--dz", "1e-9"], "dz_um"),
        (["--z", "-80", "80", "--dz", "0.001"], "dz_um"),
        (["--z", "-5000", "5000", "--dz", "1"], "10001 planes"),
        (["--iterations", "501"], "rl.iterations"),
    ):
        rc, err = cli(rec_args(tmp_path / "o.ome.tif", *flags))
        assert rc == 2 and words in err, (flags, err)
    monkeypatch.setattr(memory, "available_memory", lambda: 2 << 30)  # a 2 GiB machine
    rc, err = cli(rec_args(tmp_path / "o.ome.tif", "--z", "-80", "80", "--dz", "0.1"))
    assert rc == 2 and "GiB are free; narrow --z or take a larger --dz (e.g. --dz" in err
    assert not (tmp_path / "o.ome.tif").exists()


def test_10_file_system_faults(files, sums, cli, rec_args, tmp_path, monkeypatch):
    (tmp_path / "dir.ome.tif").mkdir()
    rc, err = cli(rec_args(tmp_path / "dir.ome.tif"))
    assert rc == 2 and "is a folder" in err
    (tmp_path / "x.zarr").write_bytes(b"not a store")
    rc, err = cli(rec_args(tmp_path / "x.zarr"))
    assert rc == 2 and "is a file, not a folder" in err and (tmp_path / "x.zarr").read_bytes() == b"not a store"
    rc, err = cli(rec_args(tmp_path / "nodir" / "o.ome.tif"))
    assert rc == 2 and "does not exist" in err
    (tmp_path / "demo.txt").write_text("mine")
    rc, err = cli(["demo", "-o", tmp_path / "demo.txt"])
    assert rc == 2 and "is a file" in err and (tmp_path / "demo.txt").read_text() == "mine"
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if os.geteuid() == 0:  # root may write anywhere: the folder reads as read-only to the check
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, mode: False if Path(p) == ro else real(p, mode))
    try:
        for argv in (rec_args(ro / "o.ome.tif"), ["demo", "-o", ro / "demo"], ["bench", "--quick", "--cache", ro]):
            rc, err = cli(argv)
            assert rc == 2 and "not writable" in err, argv
        assert not list(ro.iterdir())
    finally:
        ro.chmod(0o755)


@pytest.mark.parametrize(
    "flags, words",
    [
        (["--offset", "1e6", "1e6"], "at most half a pitch"),
        (["--offset", "nan", "0"], "finite"),
        (["--rotation", "nan"], "finite angle"),
        (["--seed", "-1"], "seed >= 0"),
    ],
)
def test_12_simulate_numbers(sums, cli, tmp_path, flags, words):
    rc, err = cli(["simulate", "bead", "-o", tmp_path / "x.tif", *flags])
    assert rc == 2 and words in err and not (tmp_path / "x.tif").exists()


def test_12_simulate_checks_every_output_first(cli, tmp_path):
    rc, err = cli(["simulate", "bead", "-o", tmp_path / "x.tif", "--flat", tmp_path / "nodir" / "f.tif"])
    assert rc == 2 and "does not exist" in err and not (tmp_path / "x.tif").exists()
    rc, err = cli(["simulate", "bead", "-o", tmp_path / "x.tif", "--flat", tmp_path / "x.tif"])
    assert rc == 2 and "would be written over the frame" in err


def test_12_bench_cache_that_is_a_file(cli, tmp_path):
    (tmp_path / "cache").write_text("x")
    rc, err = cli(["bench", "--quick", "--cache", tmp_path / "cache"])
    assert rc == 2 and "is a file" in err


def test_12_bench_without_a_writable_home_cache(cli, tmp_path, monkeypatch):
    from napari_ssdpc.validation import bench, bench_report

    home = tmp_path / "home"
    home.mkdir()
    home.chmod(0o555)
    seen = {}
    monkeypatch.setattr(bench, "default_cache", lambda: home / ".cache" / "bench")
    if os.geteuid() == 0:  # root may write anywhere: the folder reads as read-only to the check
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, mode: False if Path(p) == home else real(p, mode))
    # the benchmark itself is measured elsewhere (tests/validation): here only where its cache goes
    monkeypatch.setattr(bench, "run_bench", lambda **kw: seen.update(kw) or {})
    monkeypatch.setattr(bench_report, "format_report", lambda report: "report")
    try:
        rc, _ = cli(["bench", "--quick"])
    finally:
        home.chmod(0o755)
    cache = Path(seen["cache_dir"])
    assert rc == 0 and not (home / ".cache").exists() and cache.is_dir() and os.access(cache, os.W_OK)
    shutil.rmtree(cache)


def test_10_the_demo_never_replaces_a_file_it_did_not_write(cli, tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "white.tif").write_bytes(b"my white frame")
    (folder / "notes.txt").write_text("kept")
    rc, err = cli(["demo", "-o", folder])
    assert rc == 2 and "white.tif would replace a file napari-ssdpc did not write" in err and "--overwrite" in err
    assert (folder / "white.tif").read_bytes() == b"my white frame" and sorted(p.name for p in folder.iterdir()) == [
        "notes.txt",
        "white.tif",
    ]
    rc, err = cli(["demo", "-o", folder, "--seed", "-1"])
    assert rc == 2 and "seed >= 0" in err
    # the refinement's files are checked as well, before any work
    (folder / "white.tif").unlink()
    (folder / "refined.png").write_bytes(b"my figure")
    rc, err = cli(["demo", "-o", folder, "--refine"])
    assert rc == 2 and "refined.png would replace a file napari-ssdpc did not write" in err
    assert (folder / "refined.png").read_bytes() == b"my figure"


def test_10_files_we_wrote_are_known_as_ours(files, tmp_path):
    """Frames and overlays carry the napari-ssdpc stamp, so a rerun may replace them; a user's
    TIFF or PNG does not."""
    from napari_ssdpc.calibration import Calibration, overlay_png
    from napari_ssdpc.io.frames import write_tiff
    from napari_ssdpc.io.paths import is_ours
    from napari_ssdpc.validation.figures import _plt

    white = tifffile.imread(files / "white.tif")
    write_tiff(tmp_path / "ours.tif", white)
    tifffile.imwrite(tmp_path / "theirs.tif", white)
    overlay_png(white, Calibration.from_json(files / "cal.json"), tmp_path / "ours.png")
    plt = _plt()
    fig = plt.figure()
    fig.savefig(tmp_path / "theirs.png")
    plt.close(fig)
    assert is_ours(tmp_path / "ours.tif") and is_ours(tmp_path / "ours.png")
    assert not is_ours(tmp_path / "theirs.tif") and not is_ours(tmp_path / "theirs.png")


# ------------------------------------------------------- 13: the right fix named
def test_13_messages_name_the_right_fix(synthetic_series, files, sums, cli, rec_args, tmp_path):
    flat = synthetic_series[2]
    rgb = tmp_path / "rgb.tif"
    tifffile.imwrite(rgb, np.zeros((64, 80, 3), np.uint8), photometric="rgb")
    sat = tmp_path / "sat.tif"
    tifffile.imwrite(sat, np.full_like(flat, 65535))
    ri = tmp_path / "ri.ome.tif"
    assert cli(rec_args(ri))[0] == 0
    for raw, words, wrong in (
        (rgb, "colour (RGB) image", "frames"),
        (sat, "camera was saturated", "lamp on"),
        (ri, "reconstruction result", "frames"),
    ):
        args = rec_args(tmp_path / "o.ome.tif")
        args[1] = raw
        rc, err = cli(args)
        assert rc == 2 and words in err and wrong not in err, err
    rc, err = cli(["calibrate", rgb, "-o", tmp_path / "c.json"])
    assert rc == 2 and "colour (RGB)" in err
    argv = ["reconstruct", "r.tif", "--calibration", "c.json", "--z", "-1e3", "1e3", "-o", "o"]
    assert build_parser().parse_args(argv).z == [-1000.0, 1000.0]


def test_13_messages_cite_only_files_of_the_repository():
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    for sub in ("cli", "io"):
        for p in (root / "src" / "napari_ssdpc" / sub).glob("*.py"):
            text = p.read_text()
            assert "shared/" not in text and "DESIGN.md" not in text, p


@pytest.mark.parametrize(
    "error, words",
    [
        (OSError(errno.EIO, "Input/output error"), "Input/output error; check the path and the disk"),
        (OSError(errno.ENOSPC, "No space left on device"), "no space left on the device"),
        (MemoryError(), "out of memory"),
        (RecursionError(), "nested too deeply"),
    ],
)
def test_an_unforeseen_fault_is_still_one_line(cli, monkeypatch, error, words):
    design = importlib.import_module("napari_ssdpc.physics.design")  # the module, not the function

    def fail(*a, **k):
        raise error

    monkeypatch.setattr(design, "design_table", fail)
    rc, err = cli(["design"])
    assert rc == 2 and words in err


def test_calibrate_with_a_given_axis(files, sums, cli, tmp_path):
    """--axis replaces the measured axis (kept in the JSON as given); one off the frame is refused."""
    rc, err = cli(["calibrate", files / "white.tif", "-o", tmp_path / "cal.json", "--axis", "-5", "10"])
    assert rc == 2 and "--axis X Y inside it" in err and not (tmp_path / "cal.json").exists()
    assert cli(["calibrate", files / "white.tif", "-o", tmp_path / "cal.json", "--axis", "1220.5", "1030.25"])[0] == 0
    d = json.loads((tmp_path / "cal.json").read_text())
    assert d["axis_px"] == [1220.5, 1030.25] and d["kind_evidence"]["axis"] == "given" and d["axis_rms"] is None


def test_a_warning_repeated_frame_after_frame_is_shown_once_and_counted(synthetic_series, files, rec_args, tmp_path):
    """A series recorded at half the flat's exposure warns for every frame; the command line shows
    the warning once (naming frame 0) and then how many more frames gave it, not one line each."""
    import subprocess
    import sys

    import numpy as np

    _, _, _, frames, _ = synthetic_series
    series = tmp_path / "half.tif"
    tifffile.imwrite(series, (frames[:4] // 2).astype(np.uint16), photometric="minisblack")
    args = rec_args(tmp_path / "out.zarr")
    args[1] = series
    code = "import sys; from napari_ssdpc.cli.main import main; sys.exit(main(sys.argv[1:]))"
    run = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    warned = [
        ln for ln in run.stderr.splitlines() if ln.startswith("ssdpc: warning:") and "as bright as the flat" in ln
    ]
    assert len(warned) == 2, run.stderr
    assert "half.tif frame 0 is 0.50 x as bright" in warned[0]
    assert warned[1].startswith("ssdpc: warning: 3 more like ") and "frame 0 is 0.50 x as bright" in warned[1]
