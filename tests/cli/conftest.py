import hashlib

import pytest
import tifffile

from napari_ssdpc.cli.main import main


@pytest.fixture(scope="module")
def files(synthetic_series, tmp_path_factory):
    """raw.tif (one frame), flat.tif, white.tif, cal.json of the synthetic series."""
    optics, cal, flat, frames, white = synthetic_series
    d = tmp_path_factory.mktemp("cli")
    tifffile.imwrite(d / "raw.tif", frames[0])
    tifffile.imwrite(d / "flat.tif", flat)
    tifffile.imwrite(d / "white.tif", white)
    cal.to_json(d / "cal.json")
    (d / "link.tif").symlink_to(d / "raw.tif")
    return d


@pytest.fixture
def sums(files):
    """Checksums of every input file before a test; the test checks them again after."""

    def take():
        return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(files.iterdir()) if p.is_file()}

    before = take()
    yield before
    assert take() == before, "an input file was changed"


@pytest.fixture
def cli(capsys):
    """cli(argv) -> (exit code, the error line): every failure is one line, never a traceback."""
    return lambda argv: _run(argv, capsys)


def _run(argv, capsys):
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("ssdpc: error")]
    if rc != 0:
        assert rc == 2 and len(lines) == 1 and "Traceback" not in err, err
    return rc, " ".join(lines)


@pytest.fixture
def rec_args(files):
    """rec_args(out, *extra): a fast single-plane ``ssdpc reconstruct`` of raw.tif."""
    return lambda out, *extra: _rec_args(files, out, *extra)


def _rec_args(files, out, *extra):
    return [
        "reconstruct",
        files / "raw.tif",
        "--calibration",
        files / "cal.json",
        "--flat",
        files / "flat.tif",
        "--z",
        "0",
        "0",
        *extra,
        "-o",
        out,
    ]
