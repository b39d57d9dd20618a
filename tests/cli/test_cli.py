"""The ssdpc command: outputs, one-line errors, exit codes."""

import json
import shutil
import subprocess
import sys

import pytest

from napari_ssdpc.cli.main import main


def test_design_table_and_json(capsys):
    assert main(["design"]) == 0
    out = capsys.readouterr().out
    assert "Field of view D_FOV (Eq. 10)" in out and "122.55" in out and "20.68" in out and "4.22" in out
    assert main(["design", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["dof_full_um"] == pytest.approx(265.06, rel=5e-3) and d["lenslets_in_pupil"] == 32


@pytest.mark.parametrize(
    "argv, words",
    [
        (["design", "--optics", "missing.yaml"], "optics file not found"),
        (["calibrate", "missing.tif", "-o", "c.json"], "file not found"),
    ],
)
def test_bad_input_is_one_line_error(tmp_path, monkeypatch, capsys, argv, words):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ssdpc: error:") and words in err and "\n" not in err
    assert "Traceback" not in err


def test_console_script_is_installed():
    exe = shutil.which("ssdpc") or shutil.which("ssdpc", path=str(__import__("pathlib").Path(sys.executable).parent))
    assert exe, "the ssdpc console script is not on PATH"
    r = subprocess.run([exe, "design", "--optics", "nope.yaml"], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_napari_manifest_validates():
    npe2 = pytest.importorskip("npe2")
    pm = npe2.PluginManager.instance()
    pm.discover()
    mf = pm.get_manifest("napari-ssdpc")
    assert mf.name == "napari-ssdpc"
    assert all(c.id.startswith("napari-ssdpc.") for c in mf.contributions.commands)
    r = subprocess.run(
        [sys.executable, "-m", "npe2", "validate", "napari-ssdpc", "--imports"], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stdout + r.stderr


def test_simulate_names_the_phantoms_own_medium(tmp_path, monkeypatch, capsys):
    """The moving sample lies in water: simulated with 1.33 whatever the optics say, and the note
    says so, with what the calibration must use (the simulation itself is stubbed: only the note)."""
    from types import SimpleNamespace

    import numpy as np

    import napari_ssdpc.simulation.simulate as sim

    media = []

    def fake(phantom, optics, **kw):
        media.append(optics.medium_index)
        return SimpleNamespace(frame=np.zeros((optics.height_px, optics.width_px), np.uint16))

    monkeypatch.setattr(sim, "simulate", fake)
    from napari_ssdpc.cli.main import main

    assert main(["simulate", "moving", "--frames", "2", "-o", str(tmp_path / "m.tif")]) == 0
    err = capsys.readouterr().err
    assert media == [1.33, 1.33]
    assert "medium of index 1.33, not the optics' 1.518" in err and "labelled +0.188 off" in err


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--z-search", "-1"], "--z-search must be a distance"),
        (["--medium-index", "0.5"], "medium_index"),
        (["--dz", "0"], "dz"),
    ],
)
def test_beads_bad_input_is_one_line_error(cli, files, sums, extra, words):
    rc, line = cli(["beads", files / "raw.tif", "--calibration", files / "cal.json", *extra])
    assert rc == 2 and words in line


def test_beads_names_a_missing_calibration(cli, files, tmp_path):
    rc, line = cli(["beads", files / "raw.tif", "--calibration", tmp_path / "none.json"])
    assert rc == 2 and "none.json" in line


def test_a_bead_line_gives_its_numbers_and_its_check():
    from napari_ssdpc.cli.beads import bead_line
    from napari_ssdpc.reconstruction.bead import Bead

    good = Bead((0.01, -0.02, 4.5), 4.93, 1.4646, 0.1316, 3.0, 5.6, True, True, "", 0.105)
    line = bead_line(1, good)
    assert line == (
        "bead 1: centre (0.01, -0.02, 4.50) µm, diameter 4.93 µm, RI 1.4646 (Δn +0.1316), residual 3.0 x the "
        "noise; the voxel answer holds 0.10 x its Δn"
    )
    flagged = Bead((0.0, 0.0, -10.2), 4.96, 1.56, 0.227, 30.2, 4.6, True, False, "the model leaves 30.2 x the noise")
    assert bead_line(2, flagged).endswith("x the noise; CHECK: the model leaves 30.2 x the noise")


def test_ctrl_c_while_the_command_loads_is_one_line(monkeypatch, capsys):
    """The console entry loads the command (about a second of imports) inside the Ctrl-C guard."""
    import sys

    import napari_ssdpc.cli.main  # noqa: F401  (loaded, so that it can be taken away and put back)
    from napari_ssdpc.cli import entry

    class Interrupted:
        """An import hit by Ctrl-C."""

        def find_spec(self, name, path=None, target=None):
            if name == "napari_ssdpc.cli.main":
                raise KeyboardInterrupt
            return None

    monkeypatch.delitem(sys.modules, "napari_ssdpc.cli.main")
    monkeypatch.setattr(sys, "meta_path", [Interrupted(), *sys.meta_path])
    assert entry.run(["design"]) == 130
    assert capsys.readouterr().err == "ssdpc: interrupted\n"
