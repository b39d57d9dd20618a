"""A sweep of bad inputs through every public entry point: the ``ssdpc`` CLI, the Python API and
napari's readers and writer.

Every case ends in a one-line :class:`SsdpcError` (the CLI: exit code 2 and one ``ssdpc: error``
line, no traceback), or in a correct result, and no file that was there before changed (the SHA-256
of every file in the inputs' folder before and after each case). The inputs are made once per
module from the small simulated frames of ``tests/conftest.py``; the counts per entry point are
in docs/reliability.md.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
import tifffile

from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.cli.main import main
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.pipeline import sinks
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.reconstruction.checks import OPTICS_FIELDS
from napari_ssdpc.reconstruction.frame_result import z_grid
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics

pytestmark = pytest.mark.filterwarnings("ignore::napari_ssdpc.errors.SsdpcWarning")


# ------------------------------------------------------------------ the inputs, made once
@pytest.fixture(scope="module")
def base(synthetic_series, tmp_path_factory):
    """A folder of inputs, of a user's own files and of files napari-ssdpc wrote."""
    from napari_ssdpc._napari.writer import write_result

    optics, cal, flat, frames, white = synthetic_series
    d = tmp_path_factory.mktemp("sweep")
    tifffile.imwrite(d / "raw.tif", frames[0])
    tifffile.imwrite(d / "series.tif", frames[:3], photometric="minisblack")
    tifffile.imwrite(d / "flat.tif", flat)
    tifffile.imwrite(d / "white.tif", white)
    cal.to_json(d / "cal.json")
    optics.to_yaml(d / "optics.yaml")
    tifffile.imwrite(d / "user.tif", frames[1])  # a user's raw frame
    tifffile.imwrite(d / "user.ome.tif", np.ones((2, 8, 8), np.float32), ome=True, metadata={"axes": "ZYX"})
    (d / "notes.json").write_text('{"my": "notes"}')
    (d / "notes.txt").write_text("a user's notes")
    (d / "empty.tif").write_bytes(b"")
    (d / "folder").mkdir()
    (d / "user.zarr").mkdir()
    (d / "user.zarr" / "data.txt").write_text("another program's data")
    vol = np.linspace(1.50, 1.52, 2 * 16 * 16, dtype=np.float32).reshape(2, 16, 16)
    write_result(d / "ours.ome.tif", vol, voxel_um=(2.0, 0.8, 0.8), info={"quantity": "ri"})
    write_result(d / "ours.zarr", vol, voxel_um=(2.0, 0.8, 0.8), info={"quantity": "ri"})
    return d


_HASHES: dict = {}


def _digest(folder: Path) -> dict:
    """{file: SHA-256} of every file in ``folder``. A file whose size, modification and status-change
    times and inode are those of its last hash is not read again: any write changes its ctime."""
    out = {}
    for p in folder.rglob("*"):
        if p.is_file():
            st = p.stat()
            key = (str(p), st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)
            if key not in _HASHES:
                _HASHES[key] = hashlib.sha256(p.read_bytes()).hexdigest()
            out[str(p.relative_to(folder))] = _HASHES[key]
    return out


@pytest.fixture
def unchanged(base):
    """Every file of the inputs' folder is as it was after the case (new files may appear only in tmp_path)."""
    before = _digest(base)
    yield base
    after = _digest(base)
    assert {k: after.get(k) for k in before} == before, "a file that was there before changed"
    assert set(after) == set(before), f"new files among the inputs: {sorted(set(after) - set(before))}"


def _one_line(e: BaseException) -> str:
    msg = str(e)
    assert isinstance(e, SsdpcError) and msg and "\n" not in msg and "Traceback" not in msg, repr(e)
    return msg


# ------------------------------------------------------------------------------ CLI
def _cli(argv, capsys) -> tuple[int, str]:
    """rc and stderr of ``ssdpc ARGV`` run in this process: 0, or 2 with one error line."""
    capsys.readouterr()
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as e:  # argparse: one error line that names the help
        rc = int(e.code or 0)
        err = capsys.readouterr().err.strip()
        assert rc == 2 and "\n" not in err and err.count("error:") == 1 and "--help" in err, err
        return rc, err
    err = capsys.readouterr().err
    errors = [ln for ln in err.splitlines() if ln.startswith("ssdpc: error")]
    assert "Traceback" not in err, err
    if rc != 0:
        assert rc == 2 and len(errors) == 1, err
    return rc, " ".join(errors)


def _rec(d, out, *extra, raw="raw.tif", cal="cal.json", flat="flat.tif"):
    args = ["reconstruct", d / raw, "--calibration", d / cal, "--z", "0", "0", *extra, "-o", out]
    return args + (["--flat", d / flat] if flat else [])


_OPTION_CASES = {
    "z-nan": (["--z", "nan", "nan"], "finite"),
    "z-inf": (["--z", "-inf", "0"], "finite"),
    "z-reversed": (["--z", "5", "-5"], "z range is empty"),
    "z-text": (["--z", "a", "b"], "error:"),
    "z-one-value": (["--z", "5"], "error:"),
    "dz-zero": (["--dz", "0"], "dz"),
    "dz-negative": (["--dz", "-1"], "dz"),
    "dz-tiny": (["--dz", "1e-9"], "dz"),
    "dz-nan": (["--dz", "nan"], "dz"),
    "dz-inf": (["--dz", "inf"], "dz"),
    "dz-text": (["--dz", "abc"], "error:"),
    "alpha-inf": (["--alpha", "inf", "--method", "wotf"], "alpha"),
    "alpha-nan": (["--alpha", "nan", "--method", "wotf"], "alpha"),
    "alpha-negative": (["--alpha", "-1", "--method", "wotf"], "alpha"),
    "alpha-zero": (["--alpha", "0", "--method", "wotf"], "alpha"),
    "iterations-zero": (["--iterations", "0", "--method", "rl"], "iterations"),
    "iterations-huge": (["--iterations", "1000000", "--method", "rl"], "iterations"),
    "iterations-text": (["--iterations", "many"], "error:"),
    "tv-iterations-negative": (["--tv-iterations", "-3"], "iterations"),
    "tv-lambda-nan": (["--tv-lambda", "nan"], "lambda"),
    "dn-max-negative": (["--dn-max", "-0.1"], "dn"),
    "method-unknown": (["--method", "magic"], "error:"),
    "sign-unknown": (["--sign", "both"], "error:"),
    "save-unknown": (["--save", "everything"], "everything"),
    "save-empty-item": (["--save", "phase,,nonsense"], "nonsense"),
    "refraction-increment-zero": (["--refraction-increment", "0"], "refraction"),
    "device-unknown": (["--device", "tpu"], "error:"),
    "roi-text": (["--roi", "left"], "error:"),
    "scheduler-not-a-url": (["--scheduler", "notaurl"], "Dask scheduler"),
    "scheduler-empty": (["--scheduler", ""], "Dask scheduler"),
    "workers-zero": (["--workers", "0"], "workers"),
    "workers-negative": (["--workers", "-2"], "workers"),
    "workers-beyond-the-cores": (["--workers", "100000"], "cores"),
}


@pytest.mark.parametrize("case", list(_OPTION_CASES))
def test_cli_reconstruct_options(unchanged, tmp_path, capsys, case):
    extra, words = _OPTION_CASES[case]
    raw = "series.tif" if case.startswith(("scheduler", "workers")) else "raw.tif"
    out = tmp_path / ("o.zarr" if raw == "series.tif" else "o.ome.tif")
    rc, err = _cli(_rec(unchanged, out, *extra, raw=raw), capsys)
    assert rc == 2 and words.lower() in err.lower(), err
    assert not out.exists()


def _write(d: Path, name: str, content) -> str:
    """A bad input file in ``d`` (tmp_path) named ``name``: bytes, text, a JSON value or an array."""
    p = d / name
    if isinstance(content, np.ndarray):
        tifffile.imwrite(p, content)
    elif isinstance(content, bytes):
        p.write_bytes(content)
    elif isinstance(content, str):
        p.write_text(content)
    else:
        p.write_text(json.dumps(content))
    return name


def _cal_dict(base):
    return json.loads((base / "cal.json").read_text())


def _edited_cal(base, edit, sign=True):
    d = _cal_dict(base)
    edit(d)
    if sign:
        from napari_ssdpc.calibration.result import content_checksum

        d["checksum"] = content_checksum(d)
    else:
        d.pop("checksum", None)
    return d


def _swap(d):
    lens = d["lenslets"]
    r = [math.hypot(*ln["u"]) for ln in lens]
    a = int(np.argmin(r))
    b = int(np.argmax([ri if ln["fraction"] > 0.99 else 0 for ri, ln in zip(r, lens)]))
    lens[a]["centre_px"], lens[b]["centre_px"] = lens[b]["centre_px"], lens[a]["centre_px"]


_CAL_EDITS = {
    "lenslets-empty": (lambda d: d.update(lenslets=[]), "lenslets is []"),
    "pitch-nan": (lambda d: d["grid"].update(pitch_px=float("nan")), "pitch_px is nan"),
    "pitch-negative": (lambda d: d["grid"].update(pitch_px=-40.0), "pitch_px"),
    "radius-negative": (lambda d: d.update(ei_radius_px=-3), "ei_radius_px"),
    "radius-huge": (lambda d: d.update(ei_radius_px=1e9), "ei_radius_px"),
    "centre-nan": (lambda d: d["lenslets"][0].update(centre_px=[float("nan"), 3.0]), "centre_px is NaN"),
    "u-inf": (lambda d: d["lenslets"][0].update(u=[float("inf"), 0.0]), "u is NaN or inf"),
    "fraction-2": (lambda d: d["lenslets"][0].update(fraction=2.0), "fraction"),
    "frame-shape-tiny": (lambda d: d.update(frame_shape=[4, 4]), "frame_shape"),
    "axis-nan": (lambda d: d["grid"].update(axis_px=[float("nan"), 0.0]), "grid is"),
    "flip-unlike-optics": (lambda d: d["grid"].update(flip_x=True), "grid.flip_x"),
    "row-missing": (lambda d: d["lenslets"][0].pop("row"), "corrupt calibration"),
    "lenslets-not-a-list": (lambda d: d.update(lenslets=7), "corrupt calibration"),
    "version-99": (lambda d: d.update(version=99), "version 99"),
    "format-foreign": (lambda d: d.update(format="other"), "not a napari-ssdpc calibration"),
    "optics-misspelt": (lambda d: d["optics"].update(wavelenght_um=d["optics"].pop("wavelength_um")), "wavelength_um"),
    "centres-swapped": (_swap, "swapped"),
}


@pytest.mark.parametrize("signed", [True, False], ids=["resigned", "no-checksum"])
@pytest.mark.parametrize("case", list(_CAL_EDITS))
def test_cli_damaged_calibrations(unchanged, tmp_path, capsys, case, signed):
    edit, words = _CAL_EDITS[case]
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(_edited_cal(unchanged, edit, signed)))
    args = _rec(unchanged, tmp_path / "o.ome.tif")
    args[3] = cal
    rc, err = _cli(args, capsys)
    assert rc == 2 and words in err and not (tmp_path / "o.ome.tif").exists(), err
    if signed and case != "centres-swapped":  # `ssdpc resign-calibration` refuses what it cannot read
        before = cal.read_bytes()
        rc, err = _cli(["resign-calibration", cal], capsys)
        assert rc == 2 and cal.read_bytes() == before


def test_cli_an_edited_calibration_needs_resigning(unchanged, tmp_path, capsys):
    d = _cal_dict(unchanged)
    d["lenslets"][3]["centre_px"][0] += 3
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(d))
    args = _rec(unchanged, tmp_path / "o.ome.tif")
    args[3] = cal
    rc, err = _cli(args, capsys)
    assert rc == 2 and "resign-calibration" in err


_FILE_CASES = {
    # role: the argument replaced; content: what the file holds (None: the path does not exist)
    "raw-missing": ("raw", None, "not found"),
    "raw-folder": ("raw", "DIR", "folder"),
    "raw-empty": ("raw", b"", "not a readable TIFF"),
    "raw-text": ("raw", "hello", "not a readable TIFF"),
    "raw-truncated": ("raw", "TRUNC", "complete TIFF"),
    "raw-rgb": ("raw", np.zeros((64, 64, 3), np.uint8), "RGB"),
    "raw-tiny": ("raw", np.zeros((8, 8), np.uint16), "shape"),
    "raw-other-shape": ("raw", np.zeros((256, 256), np.uint16), "differs from the calibration"),
    "raw-all-zero": ("raw", "ZERO", "every pixel is 0"),
    "raw-saturated": ("raw", "SAT", "saturated"),
    "raw-noise": ("raw", "NOISE", "no light in the directly lit"),
    "raw-white": ("raw", "WHITE", "as on a white frame"),
    "raw-is-the-flat": ("raw", "FLAT", "equals the flat frame"),
    "raw-camera-moved": ("raw", "MOVED", "elemental images sit"),
    "raw-float-nan": ("raw", "NAN", "NaN/inf pixels"),
    "flat-missing": ("flat", None, "not found"),
    "flat-all-zero": ("flat", "ZERO", "every pixel is 0"),
    "flat-white": ("flat", "WHITE", "as on a white frame"),
    "flat-noise": ("flat", "NOISE", "flat frame"),
    "flat-moved": ("flat", "MOVED", "elemental images sit"),
    "flat-at-condenser-na-0.12": ("flat", "NA0.12", "condenser NA of about 0.1"),
    "flat-at-condenser-na-0.2": ("flat", "NA0.2", "condenser NA of about 0.2"),
    "flat-text": ("flat", "hello", "not a readable TIFF"),
    "cal-missing": ("cal", None, "not found"),
    "cal-empty": ("cal", b"", "corrupt calibration JSON"),
    "cal-a-tiff": ("cal", "RAWCOPY", "corrupt calibration JSON"),
    "cal-a-list": ("cal", [1, 2], "not a napari-ssdpc calibration"),
    "cal-binary": ("cal", b"\xff\xfe\x00garbage", "corrupt calibration JSON"),
    "cal-deep": ("cal", "[" * 100000 + "]" * 100000, "calibration"),
}


def _flat_at(optics, condenser_na):
    """A flat of the synthetic series' camera recorded at another condenser NA."""
    from napari_ssdpc.physics.lattice import Grid
    from napari_ssdpc.simulation.sample_free import flat_frame

    grid = Grid.nominal(optics, axis_offset_px=(3.7, -2.2), rotation_deg=0.4)  # as tests/conftest.py
    return flat_frame(optics.replace(condenser_na=condenser_na), grid=grid, rng=np.random.default_rng(3))


def _content(base, content, synthetic_series):
    optics, cal, flat, frames, white = synthetic_series
    special = {
        "ZERO": lambda: np.zeros_like(flat),
        "SAT": lambda: np.full_like(flat, 4095),
        "NOISE": lambda: np.random.default_rng(5).integers(0, 4096, flat.shape).astype(flat.dtype),
        "WHITE": lambda: white,
        "FLAT": lambda: flat,
        "MOVED": lambda: np.roll(frames[0], 8, axis=1),
        "NAN": lambda: np.where(np.arange(flat.size).reshape(flat.shape) % 97 == 0, np.nan, frames[0]).astype("f4"),
        "RAWCOPY": lambda: (base / "raw.tif").read_bytes(),
        "TRUNC": lambda: (base / "raw.tif").read_bytes()[: (base / "raw.tif").stat().st_size // 2],
        "NA0.12": lambda: _flat_at(optics, 0.12),
        "NA0.2": lambda: _flat_at(optics, 0.2),
    }
    if isinstance(content, str) and content in special:
        return special[content]()
    return content


@pytest.mark.parametrize("case", list(_FILE_CASES))
def test_cli_bad_files(unchanged, tmp_path, capsys, synthetic_series, case):
    role, content, words = _FILE_CASES[case]
    name = {"raw": "bad.tif", "flat": "badflat.tif", "cal": "bad.json"}[role]
    if isinstance(content, str) and content == "DIR":
        (tmp_path / name).mkdir()
    elif content is not None:
        _write(tmp_path, name, _content(unchanged, content, synthetic_series))
    args = _rec(unchanged, tmp_path / "o.ome.tif")
    args[{"raw": 1, "cal": 3}.get(role, -1)] = tmp_path / name
    rc, err = _cli(args, capsys)
    assert rc == 2 and words.lower() in err.lower() and not (tmp_path / "o.ome.tif").exists(), err


def _optics_edit(base, key, value):
    d = Optics.from_yaml(base / "optics.yaml").to_dict()
    if "." in key:
        part, sub = key.split(".")
        d[part] = {**d[part], sub: value}
    elif value is None:
        d.pop(key)
    else:
        d[key] = value
    return d


_OPTICS_CASES = {
    "fourier-lens-1.5x": ("fourier_lens_mm", 1.5, "Fourier-lens focal length"),
    "medium-water": ("medium_index", 1.333, "medium index"),
    "magnification-40x": ("objective.magnification", 2.0, "magnification"),
    "objective-na": ("objective.na", 0.9, "objective NA"),
    "tube-lens": ("objective.tube_lens_mm", 1.1, "tube-lens"),
    "mla-focal": ("mla.focal_length_mm", 1.2, "MLA focal length"),
    "pixel": ("sensor.pixel_um", 1.05, "pixel size"),
    "wavelength": ("wavelength_um", 1.1, "wavelength"),
    "flip-x": ("flip_x", True, "mirroring"),
    "hex-grid": ("mla.grid", "hex", "hex"),
}


@pytest.mark.parametrize("case", list(_OPTICS_CASES))
def test_cli_optics_unlike_the_calibration(unchanged, tmp_path, capsys, case):
    key, factor, words = _OPTICS_CASES[case]
    o = Optics.from_yaml(unchanged / "optics.yaml").to_dict()
    here = o[key.split(".")[0]] if "." in key else o
    old = here[key.split(".")[-1]]
    value = old * factor if isinstance(factor, float) and not isinstance(old, bool) else factor
    if key == "medium_index":
        value = factor
    (tmp_path / "o.yaml").write_text(json.dumps(_optics_edit(unchanged, key, value)))
    rc, err = _cli(_rec(unchanged, tmp_path / "o.ome.tif", "--optics", tmp_path / "o.yaml"), capsys)
    assert rc == 2 and words in err, err


_OPTICS_FILE_CASES = {
    "misspelt-wavelength": ({"wavelenght_um": 0.52}, "did you mean 'wavelength_um'"),
    "misspelt-medium": ({"medium_idx": 1.518}, "did you mean 'medium_index'"),
    "misspelt-condenser": ({"condensor_na": 0.1}, "did you mean 'condenser_na'"),
    "wavelength-in-nm": ({"wavelength_nm": 520}, "rename the key to 'wavelength_um'"),
    "unknown-key": ({"colour": "red"}, "unknown key 'colour'"),
    "quoted-number": ({"medium_index": "1.518"}, "without quotes"),
    "medium-out-of-range": ({"medium_index": 0.5}, "'medium_index' = 0.5 is outside"),
    "condenser-above-na": ({"condenser_na": 0.99}, "condenser_na"),
    "wavelength-in-nm-value": ({"wavelength_um": 520}, "wavelength_um"),
}


@pytest.mark.parametrize("command", ["reconstruct", "design"])
@pytest.mark.parametrize("case", list(_OPTICS_FILE_CASES))
def test_cli_bad_optics_files(unchanged, tmp_path, capsys, case, command):
    change, words = _OPTICS_FILE_CASES[case]
    d = Optics.from_yaml(unchanged / "optics.yaml").to_dict()
    for k, v in change.items():
        real = {"wavelenght_um": "wavelength_um", "medium_idx": "medium_index", "condensor_na": "condenser_na"}
        d.pop(real.get(k, "wavelength_um" if k == "wavelength_nm" else k), None)
        d[k] = v
    (tmp_path / "o.yaml").write_text(json.dumps(d))
    if command == "design":
        args = ["design", "--optics", tmp_path / "o.yaml"]
    else:
        args = _rec(unchanged, tmp_path / "o.ome.tif", "--optics", tmp_path / "o.yaml")
    rc, err = _cli(args, capsys)
    assert rc == 2 and words in err, err


_OUTPUT_CASES = {
    "user-raw-tif": ("user.tif", "did not write"),
    "user-ome-tif": ("user.ome.tif", "did not write"),
    "the-raw-input": ("raw.tif", "would overwrite the"),
    "the-calibration": ("cal.json", "would overwrite the"),
    "a-folder": ("folder", "folder"),
    "missing-folder": ("nowhere/o.ome.tif", "does not exist"),
    "foreign-store": ("user.zarr", "not written by"),
    "zarr-is-a-file": ("notes.txt", "did not write"),
}


@pytest.mark.parametrize("case", list(_OUTPUT_CASES))
def test_cli_outputs_never_replace_a_file(unchanged, capsys, case):
    target, words = _OUTPUT_CASES[case]
    raw = "series.tif" if target.endswith(".zarr") else "raw.tif"
    rc, err = _cli(_rec(unchanged, unchanged / target, raw=raw), capsys)
    assert rc == 2 and words in err, err


_OTHER_COMMANDS = {
    "calibrate-over-notes": (["calibrate", "{d}/white.tif", "-o", "{d}/notes.json"], "did not write"),
    "calibrate-over-white": (["calibrate", "{d}/white.tif", "-o", "{d}/white.tif"], "would overwrite"),
    "calibrate-zero-frame": (["calibrate", "{t}/zero.tif", "-o", "{t}/c.json"], "every pixel is 0"),
    "calibrate-text": (["calibrate", "{d}/notes.txt", "-o", "{t}/c.json"], "not a readable TIFF"),
    "resign-foreign-json": (["resign-calibration", "{d}/notes.json"], "not a napari-ssdpc calibration"),
    "resign-missing": (["resign-calibration", "{t}/none.json"], "not found"),
    "resign-a-tiff": (["resign-calibration", "{d}/raw.tif"], "corrupt calibration JSON"),
    "design-missing-optics": (["design", "--optics", "{t}/none.yaml"], "not found"),
    "design-optics-is-tiff": (["design", "--optics", "{d}/raw.tif"], "optics"),
    "simulate-over-user": (["simulate", "bead", "-o", "{d}/user.tif"], "did not write"),
    "simulate-seed-negative": (["simulate", "bead", "-o", "{t}/s.tif", "--seed", "-1"], "seed"),
    "simulate-rotation-nan": (["simulate", "bead", "-o", "{t}/s.tif", "--rotation", "nan"], "rotation"),
    "demo-seed-negative": (["demo", "-o", "{t}/demo", "--seed", "-1"], "seed"),
    "unknown-command": (["fly"], "error:"),
}


@pytest.mark.parametrize("case", list(_OTHER_COMMANDS))
def test_cli_other_commands(unchanged, tmp_path, capsys, case):
    argv, words = _OTHER_COMMANDS[case]
    tifffile.imwrite(tmp_path / "zero.tif", np.zeros((256, 256), np.uint16))
    rc, err = _cli([a.format(d=unchanged, t=tmp_path) for a in argv], capsys)
    assert rc == 2 and words in err, err


def test_cli_design_and_the_output_name_the_medium_index(unchanged, tmp_path, capsys):
    """Correct results: `ssdpc design` shows the medium index, and a reconstruction records it."""
    assert main(["design", "--optics", str(unchanged / "optics.yaml")]) == 0
    assert "Medium index n_medium (RI = n_medium + Δn)" in capsys.readouterr().out
    d = Optics.from_yaml(unchanged / "optics.yaml").to_dict()
    (tmp_path / "water.yaml").write_text(json.dumps({**d, "medium_index": 1.333}))
    assert main(["design", "--optics", str(tmp_path / "water.yaml"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["medium_index"] == 1.333
    out = tmp_path / "o.ome.tif"
    rc, err = _cli(_rec(unchanged, out), capsys)
    assert rc == 0, err
    from napari_ssdpc._napari.reader import _our_description
    from napari_ssdpc.io.frames import tiff_info

    desc = _our_description(tiff_info(out))
    assert desc["settings"]["medium_index"] == 1.518 and desc["optics"]["medium_index"] == 1.518


# ------------------------------------------------------------------------------ API
@pytest.fixture(scope="module")
def api(base, synthetic_series):
    optics, cal, flat, frames, white = synthetic_series
    config = RunConfig.of(optics, z_min_um=0, z_max_um=0)
    return optics, cal, flat, frames, white, config


def _config(api, **kw):
    return RunConfig.of(api[0], **kw)


_API_BUILD = {
    "config-none": (lambda a: Reconstructor(None, a[1]), "takes a RunConfig"),
    "config-optics": (lambda a: Reconstructor(a[0], a[1]), "takes a RunConfig"),
    "calibration-none": (lambda a: Reconstructor(a[5], None), "takes a Calibration"),
    "calibration-path": (lambda a: Reconstructor(a[5], "cal.json"), "takes a Calibration"),
    "calibration-dict": (lambda a: Reconstructor(a[5], a[1].to_dict()), "takes a Calibration"),
    "flat-path": (lambda a: Reconstructor(a[5], a[1], flat="flat.tif"), "not a grey-level image"),
    "flat-list": (lambda a: Reconstructor(a[5], a[1], flat=[1, 2, 3]), "expected a 2D frame"),
    "flat-small": (lambda a: Reconstructor(a[5], a[1], flat=np.ones((10, 10))), "too small"),
    "flat-3d": (lambda a: Reconstructor(a[5], a[1], flat=a[3][:2]), "expected a 2D frame"),
    "flat-nan": (lambda a: Reconstructor(a[5], a[1], flat=np.full(a[2].shape, np.nan)), "NaN/inf"),
    "flat-zero": (lambda a: Reconstructor(a[5], a[1], flat=np.zeros_like(a[2])), "every pixel is 0"),
    "flat-white": (lambda a: Reconstructor(a[5], a[1], flat=a[4]), "as on a white frame"),
    "flat-is-a-sample-frame-rolled": (lambda a: Reconstructor(a[5], a[1], flat=np.roll(a[2], 9, 0)), "sit"),
    "dark-nan": (lambda a: Reconstructor(a[5], a[1], flat=a[2], dark=math.nan), "dark"),
    "dark-negative": (lambda a: Reconstructor(a[5], a[1], flat=a[2], dark=-1), "dark"),
    "dark-text": (lambda a: Reconstructor(a[5], a[1], flat=a[2], dark="10"), "dark"),
    "min-light-text": (lambda a: Reconstructor(a[5], a[1], flat=a[2], min_light="a"), "min_light"),
    "min-light-zero": (lambda a: Reconstructor(a[5], a[1], flat=a[2], min_light=0), "min_light"),
    "min-light-nan": (lambda a: Reconstructor(a[5], a[1], flat=a[2], min_light=math.nan), "min_light"),
    "min-light-bool": (lambda a: Reconstructor(a[5], a[1], flat=a[2], min_light=True), "min_light"),
    "progress-int": (lambda a: Reconstructor(a[5], a[1], flat=a[2], progress=3), "progress"),
    "method-name": (lambda a: Reconstructor(a[5], a[1], flat=a[2], method="tv"), "method"),
    "method-int": (lambda a: Reconstructor(a[5], a[1], flat=a[2], method=1), "method"),
    "memory": (lambda a: Reconstructor(_config(a, z_min_um=-1000, z_max_um=1000, dz_um=1.0), a[1]), "GiB are free"),
}


@pytest.mark.parametrize("case", list(_API_BUILD))
def test_api_reconstructor_arguments(unchanged, api, case, monkeypatch):
    from napari_ssdpc.reconstruction import memory

    monkeypatch.setattr(memory, "available_memory", lambda: 8 << 30)  # the same 8 GiB on every machine
    make, words = _API_BUILD[case]
    with pytest.raises(Exception) as e:
        make(api)
    assert words in _one_line(e.value)


@pytest.mark.parametrize("attr", [f[1] for f in OPTICS_FIELDS])
def test_api_every_optics_field_is_compared_with_the_calibration(unchanged, api, attr):
    optics = api[0]
    value = getattr(optics, attr)
    if isinstance(value, bool):
        changed = optics.replace(**{attr: not value})
    elif attr == "medium_index":
        changed = optics.replace(medium_index=value - 0.01)
    elif attr == "na":
        changed = optics.replace(na=value * 1.2)
    elif attr == "lenslet_radius_um":
        changed = optics.replace(lenslet_radius_um=value * 0.9)
    else:
        changed = optics.replace(**{attr: value * 1.05})
    with pytest.raises(SsdpcError) as e:
        Reconstructor(RunConfig.of(changed, z_min_um=0, z_max_um=0), api[1], flat=api[2])
    assert "disagree" in _one_line(e.value)


_API_CONFIG = {
    "optics-none": (lambda o: RunConfig.of(None), "takes an Optics"),
    "optics-path": (lambda o: RunConfig.of("optics.yaml"), "takes an Optics"),
    "z-nan": (lambda o: RunConfig.of(o, z_min_um=math.nan, z_max_um=math.nan), "finite"),
    "z-inf": (lambda o: RunConfig.of(o, z_min_um=-math.inf), "finite"),
    "z-text": (lambda o: RunConfig.of(o, z_min_um="0"), "z_min_um"),
    "dz-tiny": (lambda o: RunConfig.of(o, dz_um=1e-9), "dz_um"),
    "dz-zero": (lambda o: RunConfig.of(o, dz_um=0), "dz_um"),
    "planes-too-many": (lambda o: RunConfig.of(o, z_min_um=-2000, z_max_um=2000, dz_um=0.05), "planes"),
    "alpha-inf": (lambda o: RunConfig.of(o, wotf={"alpha": math.inf}), "alpha"),
    "alpha-zero": (lambda o: RunConfig.of(o, wotf={"alpha": 0.0}), "alpha"),
    "method-unknown": (lambda o: RunConfig.of(o, method="magic"), "method"),
    "unknown-key": (lambda o: RunConfig.of(o, zmin=3), "did you mean"),
    "unknown-section": (lambda o: RunConfig.of(o, foo={"a": 1}), "foo"),
    "section-not-a-mapping": (lambda o: RunConfig.of(o, tv=3), "tv"),
    "iterations-negative": (lambda o: RunConfig.of(o, tv={"iterations": -1}), "iterations"),
    "iterations-float": (lambda o: RunConfig.of(o, tv={"iterations": 2.5}), "iterations"),
    "save-unknown": (lambda o: RunConfig.of(o, save=["everything"]), "everything"),
    "save-number": (lambda o: RunConfig.of(o, save=3), "save"),
    "reconstruction-text": (lambda o: RunConfig.of(o, "tv"), "ReconstructionSettings"),
    "optics-misspelt": (lambda o: Optics.from_dict({**o.to_dict(), "wavelenght_um": 0.5}), "wavelenght_um"),
    "optics-not-a-dict": (lambda o: Optics.from_dict([1]), "mapping"),
    "calibration-from-none": (lambda o: Calibration.from_json(None), "path"),
    "calibration-from-folder": (lambda o: Calibration.from_json("."), "not found"),
    "calibration-dict-none": (lambda o: Calibration.from_dict(None), "not a napari-ssdpc calibration"),
}


@pytest.mark.parametrize("case", list(_API_CONFIG))
def test_api_settings_and_files(unchanged, api, case):
    make, words = _API_CONFIG[case]
    with pytest.raises(Exception) as e:
        make(api[0])
    assert words in _one_line(e.value)


def _pipeline(a):
    return Pipeline(Job(a[5], a[1], a[2]), reconstructor=object())  # refused before the reconstructor is used


def _sinks():
    return sinks


_API_PIPELINE = {
    "z-grid-tiny-dz": (lambda a: _z_grid()(0, 1e6, 1e-9), "at most"),
    "z-grid-nan": (lambda a: _z_grid()(math.nan, math.nan, 1.0), "finite"),
    "z-grid-text": (lambda a: _z_grid()("0", 1, 1), "finite"),
    "pipeline-none": (lambda a: Pipeline(None), "takes a Job"),
    "job-none": (
        lambda a: __import__("napari_ssdpc.pipeline.job", fromlist=["x"]).Job(None, a[1]).build(),
        "RunConfig",
    ),
    "source-none": (lambda a: _pipeline(a).run(None, _sinks().MemorySink(), progress=False), "TIFF path"),
    "source-list": (lambda a: _pipeline(a).run([1, 2], _sinks().MemorySink(), progress=False), "TIFF path"),
    "source-4d": (lambda a: _pipeline(a).run(np.zeros((2, 2, 64, 64)), _sinks().MemorySink()), "(t, y, x)"),
    "source-missing": (lambda a: _pipeline(a).run("/no/such.tif", _sinks().MemorySink()), "not found"),
    "sink-none": (lambda a: _pipeline(a).run(a[3][:1], None, progress=False), "Sink"),
    "sink-path": (lambda a: _pipeline(a).run(a[3][:1], "out.zarr", progress=False), "Sink"),
    "stop-after-negative": (lambda a: _pipeline(a).run(a[3][:1], _sinks().MemorySink(), stop_after=-1), "stop_after"),
    "stop-after-text": (lambda a: _pipeline(a).run(a[3][:1], _sinks().MemorySink(), stop_after="a"), "stop_after"),
    "zarr-sink-none": (lambda a: _sinks().ZarrSink(None), "path"),
    "zarr-sink-save": (lambda a: _sinks().ZarrSink("x.zarr", ["everything"]), "everything"),
    "tiff-sink-none": (lambda a: _sinks().OmeTiffSink(None), "'ri'"),
}


def _z_grid():
    return z_grid


@pytest.mark.parametrize("case", list(_API_PIPELINE))
def test_api_pipeline_arguments(unchanged, api, case):
    make, words = _API_PIPELINE[case]
    with pytest.raises(Exception) as e:
        make(api)
    assert words in _one_line(e.value)


@pytest.fixture(scope="module")
def rec(api):
    return Reconstructor(api[5], api[1], flat=api[2])


_API_FRAMES = {
    "none": (lambda a: None, {}, "not a grey-level image"),
    "text": (lambda a: "raw.tif", {}, "not a grey-level image"),
    "3d": (lambda a: a[3][:2], {}, "pass one frame"),
    "complex": (lambda a: a[3][0].astype(complex), {}, "not a grey-level image"),
    "bool": (lambda a: a[3][0] > 100, {}, "not a grey-level image"),
    "small": (lambda a: np.ones((8, 8)), {}, "too small"),
    "other-shape": (lambda a: a[3][0][:-16], {}, "differs from the calibration"),
    "nan": (lambda a: np.full(a[2].shape, np.nan), {}, "NaN/inf"),
    "zero": (lambda a: np.zeros_like(a[2]), {}, "every pixel is 0"),
    "saturated": (lambda a: np.full_like(a[2], 4095), {}, "saturated"),
    "white": (lambda a: a[4], {}, "as on a white frame"),
    "the-flat": (lambda a: a[2], {}, "equals the flat frame"),
    "moved": (lambda a: np.roll(a[3][0], 6, axis=0), {}, "elemental images sit"),
    "warm-text": (lambda a: a[3][0], {"warm": "x"}, "warm"),
    "progress-int": (lambda a: a[3][0], {"progress": 3}, "progress"),
    "should-stop-int": (lambda a: a[3][0], {"should_stop": 1}, "should_stop"),
}


@pytest.mark.parametrize("case", list(_API_FRAMES))
def test_api_bad_frames(unchanged, api, rec, case):
    make, kw, words = _API_FRAMES[case]
    with pytest.raises(Exception) as e:
        rec.reconstruct(make(api), **kw)
    assert words in _one_line(e.value)


@pytest.mark.parametrize("scale", [0.5, 1.5, 4.0])
def test_api_an_exposure_change_gives_the_same_numbers(unchanged, api, rec, scale):
    """A correct result: the frame at another exposure is normalised, reported and Δn kept."""
    frame = api[3][0].astype(np.float64)
    ref = rec.reconstruct(frame)
    with pytest.warns(Warning, match="as bright as the flat"):
        got = rec.reconstruct(frame * scale)
    assert got.settings["exposure_ratio"] == pytest.approx(scale, rel=0.03)
    peak = float(np.abs(ref.delta_n).max())
    assert float(np.abs(got.delta_n - ref.delta_n).max()) < 0.15 * peak
    assert got.settings["medium_index"] == api[0].medium_index
    np.testing.assert_allclose(got.ri - got.delta_n, api[0].medium_index, atol=1e-6)


# ------------------------------------------------------------------------- napari
def _damage_store(store: Path, how: str) -> None:
    import zarr

    g = zarr.open_group(str(store / "ri"), mode="r+")
    attrs = dict(g.attrs)
    ms = attrs["multiscales"][0]
    if how == "scale-nan":
        ms["datasets"][0]["coordinateTransformations"][0]["scale"] = [float("nan")] * 3
    elif how == "scale-zero":
        ms["datasets"][0]["coordinateTransformations"][0]["scale"] = [0.0, 1.0, 1.0]
    elif how == "scale-short":
        ms["datasets"][0]["coordinateTransformations"][0]["scale"] = [1.0]
    elif how == "no-datasets":
        ms["datasets"] = []
    elif how == "no-axes":
        ms.pop("axes")
    elif how == "axes-wrong":
        ms["axes"] = [{"name": "q"}, {"name": "w"}, {"name": "e"}]
    elif how == "dataset-missing":
        ms["datasets"][0]["path"] = "nope"
    elif how == "origin-text":
        attrs["napari_ssdpc"] = {**attrs["napari_ssdpc"], "origin_um": "abc"}
    elif how == "transforms-missing":
        ms["datasets"][0].pop("coordinateTransformations")
    elif how == "multiscales-text":
        attrs["multiscales"] = "broken"
    attrs["multiscales"] = attrs["multiscales"] if how == "multiscales-text" else [ms]
    g.attrs.clear()
    g.attrs.update(attrs)


_STORE_DAMAGE = [
    "scale-nan",
    "scale-zero",
    "scale-short",
    "no-datasets",
    "no-axes",
    "axes-wrong",
    "dataset-missing",
    "origin-text",
    "transforms-missing",
    "multiscales-text",
]


@pytest.mark.parametrize("how", _STORE_DAMAGE)
def test_napari_reader_on_our_damaged_stores(unchanged, tmp_path, how):
    import shutil

    from napari_ssdpc._napari.reader import get_result_reader

    store = tmp_path / "r.zarr"
    shutil.copytree(unchanged / "ours.zarr", store)
    _damage_store(store, how)
    reader = get_result_reader(str(store))
    if reader is None:
        return  # not recognised as ours: napari tries another reader
    try:
        layers = reader(str(store))
    except Exception as e:
        _one_line(e)
        return
    for _data, kw, kind in layers:  # read: then every number a layer carries is sane
        assert kind == "image" and all(math.isfinite(s) and s > 0 for s in kw.get("scale", (1,)))


_TIFF_DAMAGE = {
    "voxel-nan": lambda d: d.update(voxel_um=[float("nan")] * 3),
    "origin-text": lambda d: d.update(origin_um="abc"),
    "z-text": lambda d: (d.pop("origin_um"), d.update(z_um="abc")),
    "settings-text": lambda d: (d.pop("origin_um"), d.update(settings="x")),
    "channels-wrong": lambda d: d.update(quantity="dpc", channels=7),
}


@pytest.mark.parametrize("how", list(_TIFF_DAMAGE))
def test_napari_reader_on_our_damaged_ome_tiffs(unchanged, tmp_path, how):
    from napari_ssdpc._napari.reader import get_result_reader
    from napari_ssdpc.io.frames import write_ome_tiff

    desc = {"format": "napari-ssdpc-result", "version": 1, "quantity": "ri", "software": "napari-ssdpc"}
    desc["origin_um"] = [0.0, 0.0, 0.0]
    _TIFF_DAMAGE[how](desc)
    p = tmp_path / "r.ome.tif"
    write_ome_tiff(p, np.ones((2, 8, 8), np.float32), axes="ZYX", voxel_um=(1, 1, 1), description=desc)
    reader = get_result_reader(str(p))
    if reader is None:
        return
    try:
        layers = reader(str(p))
    except Exception as e:
        _one_line(e)
        return
    assert layers and all(kind == "image" for _, _, kind in layers)


_FOREIGN = {
    "empty-tif": ("empty.tif", None),
    "text-as-tif": ("x.tif", b"not a tiff at all"),
    "json-list": ("x.json", b"[1, 2]"),
    "json-binary": ("x.json", b"\xff\xfe\x00"),
    "json-deep": ("x.json", b"[" * 100000),
    "empty-zarr": ("x.zarr", "DIR"),
    "user-store": ("user.zarr", None),
    "user-ome": ("user.ome.tif", None),
    "notes": ("notes.txt", None),
}


@pytest.mark.parametrize("reader_name", ["get_raw_reader", "get_calibration_reader", "get_result_reader"])
@pytest.mark.parametrize("case", list(_FOREIGN))
def test_napari_readers_on_foreign_files(unchanged, tmp_path, case, reader_name):
    from napari_ssdpc._napari import reader as readers

    name, content = _FOREIGN[case]
    p = unchanged / name
    if content == "DIR":
        p = tmp_path / name
        p.mkdir()
    elif content is not None:
        p = tmp_path / name
        p.write_bytes(content)
    get = getattr(readers, reader_name)
    reader = get(str(p))
    if reader is not None:  # a raw frame reader may take a user's TIFF: it must read it then
        try:
            assert reader(str(p))
        except Exception as e:
            _one_line(e)


_VOL = np.linspace(1.5, 1.52, 2 * 16 * 16, dtype=np.float32).reshape(2, 16, 16)

_WRITER = {
    "data-none": (None, {}, "no numeric image"),
    "data-text": ("abc", {}, "no numeric image"),
    "data-empty-list": ([], {}, "no numeric image"),
    "data-complex": (_VOL.astype(complex), {}, "no numeric image"),
    "data-2d": (_VOL[0], {}, "dimensions"),
    "data-5d": (_VOL[None, None], {}, "dimensions"),
    "meta-none": (_VOL, None, None),
    "meta-text": (_VOL, "x", None),
    "scale-2-values": (_VOL, {"scale": (1.0, 1.0)}, "2 values for 3 axes"),
    "scale-zero": (_VOL, {"scale": (0.0, 1.0, 1.0)}, "voxel size"),
    "scale-negative": (_VOL, {"scale": (1.0, -1.0, 1.0)}, "voxel size"),
    "scale-nan": (_VOL, {"scale": (1.0, 1.0, float("nan"))}, "voxel size"),
    "scale-inf": (_VOL, {"scale": (float("inf"), 1.0, 1.0)}, "voxel size"),
    "scale-text": (_VOL, {"scale": "big"}, "not a list of numbers"),
    "translate-nan": (_VOL, {"translate": (float("nan"), 0, 0)}, "origin"),
    "translate-short": (_VOL, {"translate": (0.0,)}, "1 values for 3 axes"),
    "quantity-slash": (_VOL, {"metadata": {"ssdpc": {"quantity": "a/b"}}}, "quantity name"),
    "quantity-dotdot": (_VOL, {"metadata": {"ssdpc": {"quantity": ".."}}}, "quantity name"),
    "quantity-parent": (_VOL, {"metadata": {"ssdpc": {"quantity": "../../x"}}}, "quantity name"),
    "quantity-empty": (_VOL, {"metadata": {"ssdpc": {"quantity": ""}}}, "quantity name"),
    "metadata-text": (_VOL, {"metadata": "x"}, None),
    "ssdpc-metadata-list": (_VOL, {"metadata": {"ssdpc": [1]}}, None),
    "metadata-object": (_VOL, {"metadata": {"ssdpc": {"quantity": "ri", "thing": object()}}}, None),
}


@pytest.mark.parametrize("suffix", [".ome.tif", ".zarr"])
@pytest.mark.parametrize("case", list(_WRITER))
def test_napari_writer_bad_layers(unchanged, tmp_path, case, suffix):
    from napari_ssdpc._napari.reader import get_result_reader
    from napari_ssdpc._napari.writer import write_volume

    data, meta, words = _WRITER[case]
    out = tmp_path / f"out{suffix}"
    if words is None:  # a correct result: written and read back with the same numbers
        [written] = write_volume(str(out), data, meta)
        layers = get_result_reader(written)(written)
        np.testing.assert_array_equal(np.asarray(layers[0][0]), data)
        return
    with pytest.raises(Exception) as e:
        write_volume(str(out), data, meta)
    assert words in _one_line(e.value) and not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


_WRITER_TARGETS = {
    "user-ome-tif": ("user.ome.tif", "did not write"),
    "user-raw-tif": ("user.tif", "NAME.ome.tif"),
    "user-store": ("user.zarr", "did not write"),
    "a-file-as-store": ("notes.txt", "NAME.ome.tif"),
    "raw-frame": ("raw.tif", "NAME.ome.tif"),
    "missing-folder": ("nowhere/x.zarr", "does not exist"),
    "png": ("x.png", "NAME.ome.tif"),
}


@pytest.mark.parametrize("case", list(_WRITER_TARGETS))
def test_napari_writer_never_replaces_a_file(unchanged, case):
    from napari_ssdpc._napari.writer import write_volume

    target, words = _WRITER_TARGETS[case]
    with pytest.raises(Exception) as e:
        write_volume(str(unchanged / target), _VOL, {"scale": (1, 1, 1)})
    assert words in _one_line(e.value)


def test_napari_writer_replaces_its_own_file(base, tmp_path):
    """A correct result: a file napari-ssdpc wrote is replaced (on a copy of it)."""
    from napari_ssdpc._napari.reader import read_result
    from napari_ssdpc._napari.writer import write_volume

    own = tmp_path / "ours.ome.tif"
    own.write_bytes((base / "ours.ome.tif").read_bytes())
    write_volume(str(own), _VOL + 1, {"scale": (2.0, 0.5, 0.5)})
    [(data, kw, _)] = read_result(own)
    np.testing.assert_array_equal(np.asarray(data), _VOL + 1)
    assert list(kw["scale"])[-3:] == [2.0, 0.5, 0.5]


def sweep_counts() -> dict:
    """Cases of this sweep per entry point."""
    cli = (
        len(_OPTION_CASES)
        + 2 * len(_CAL_EDITS)
        + 1
        + len(_FILE_CASES)
        + len(_OPTICS_CASES)
        + 2 * len(_OPTICS_FILE_CASES)
        + len(_OUTPUT_CASES)
        + len(_OTHER_COMMANDS)
        + 1
    )
    api = len(_API_BUILD) + len(OPTICS_FIELDS) + len(_API_CONFIG) + len(_API_FRAMES) + len(_API_PIPELINE) + 3
    napari = len(_STORE_DAMAGE) + len(_TIFF_DAMAGE) + 3 * len(_FOREIGN) + 2 * len(_WRITER) + len(_WRITER_TARGETS) + 1
    return {"cli": cli, "api": api, "napari": napari}


def test_the_sweep_is_large_enough():
    """At least 150 bad inputs across the three entry points (counts in docs/reliability.md)."""
    counts = sweep_counts()
    assert sum(counts.values()) >= 150 and min(counts.values()) >= 30, counts
