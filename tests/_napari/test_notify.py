"""The dock's toasts say the core's messages in the dock's words, not the command line's flags."""

import pytest

pytest.importorskip("napari")

from napari_ssdpc._napari.notify import gui_words


@pytest.mark.parametrize(
    "core, dock",
    [
        (
            "'tv' underestimates such objects; reconstruct with --method multislice",
            "'tv' underestimates such objects; choose the phase method 'multislice' (Method tab)",
        ),
        (
            "needs 30 GiB but 4.0 GiB are free; narrow --z or take a larger --dz (e.g. --dz 2)",
            "needs 30 GiB but 4.0 GiB are free; narrow z min / z max (Method tab) or take a larger dz (Method tab) "
            "(e.g. dz 2 µm)",
        ),
        (
            "give a region inside it (--roi)",
            "give a region inside it (a Shapes layer as the multislice region, Reconstruct tab)",
        ),
        ("Check --dz and --alpha", "Check dz (Method tab) and the Tikhonov α (Reconstruct tab)"),
        ("raise tv.warm_iterations (--tv-warm-iterations)", "raise tv.warm_iterations (in the run configuration)"),
        (
            "check the optics (`ssdpc fit-optics` fits them to a frame of beads)",
            "check the optics (Fit the optics in the Calibrate tab fits them to a frame of beads)",
        ),
    ],
)
def test_flags_become_the_dock_s_words(core, dock):
    assert gui_words(core) == dock and "--" not in gui_words(core)


def test_the_core_s_flag_messages_are_all_translated():
    """Every flag a reconstruction's message names has its words in the dock (the calibration's
    ``--axis X Y`` has no field in the dock: its message names the command)."""
    import re
    from pathlib import Path

    import napari_ssdpc

    root = Path(napari_ssdpc.__file__).parent
    flags = set()
    for folder in ("reconstruction", "physics"):
        for path in (root / folder).rglob("*.py"):
            for line in path.read_text(encoding="utf-8").splitlines():
                if '"' in line and not line.strip().startswith("#"):
                    flags.update(re.findall(r"--[a-z][a-z-]*(?: [a-z0-9]+)?", line))
    left = {f for f in flags if "--" in gui_words(f"({f})") and "--" in gui_words(f"reconstruct with {f}")}
    assert not left, f"core messages name flags the dock does not translate: {sorted(left)}"


def test_the_condenser_warning_names_the_fit_in_the_dock():
    import warnings

    from napari_ssdpc.reconstruction.consistency import warn_condenser_na
    from napari_ssdpc.settings.optics import Optics

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_condenser_na((0.262, 5.0, 1e-3), Optics.paper().replace(condenser_na=0.25), "flat frame", True)
    text = gui_words(str(caught[0].message))
    assert "with Fit the optics (Calibrate tab)" in text and "--" not in text


def test_the_instruments_notices_name_the_fit_in_the_dock():
    from napari_ssdpc.calibration.view_focus import rims_notice

    for note in (rims_notice(0.47), rims_notice(0.47, "the calibration's white frame")):
        text = gui_words(note)
        assert "with Fit the optics (Calibrate tab: the bead frame, the flat and the white frame)" in text
        assert "--" not in text and "`ssdpc" not in text


def test_a_calibration_fitted_in_another_medium_names_the_fit_in_the_dock():
    from types import SimpleNamespace

    from napari_ssdpc.errors import SsdpcError
    from napari_ssdpc.reconstruction.checks import check_optics_match
    from napari_ssdpc.settings.optics import Optics

    water = Optics.paper().replace(medium_index=1.33)
    cal = SimpleNamespace(optics=water, optics_fit={"pupil": {}})  # what the check reads first
    with pytest.raises(SsdpcError) as err:
        check_optics_match(Optics.paper(), cal)
    text = gui_words(err.value)
    assert "Fit the optics in the Calibrate tab, on a frame of beads in it, the medium's index 1.518" in text
    assert "--" not in text and "`ssdpc" not in text
