import gc
import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def shared_optics_path():
    """The paper's optics as documented in docs/paper-optics.yaml."""
    return ROOT / "docs" / "paper-optics.yaml"


@pytest.fixture(scope="session")
def synthetic_series(tmp_path_factory):
    """(optics, calibration, flat, frames, white): white/flat frames of the paper's optics and 12
    frames of the flat frame with smooth random modulations, for the series and bench tests."""
    from scipy import ndimage

    from napari_ssdpc.calibration import calibrate
    from napari_ssdpc.physics.lattice import Grid
    from napari_ssdpc.settings.optics import Optics
    from napari_ssdpc.simulation.sample_free import flat_frame, white_frame

    optics = Optics.paper()
    grid = Grid.nominal(optics, axis_offset_px=(3.7, -2.2), rotation_deg=0.4)
    rng = np.random.default_rng(0)
    white = white_frame(optics, grid=grid, rng=rng)
    flat = flat_frame(optics, grid=grid, rng=rng)
    frames = []
    for _ in range(12):
        field = ndimage.zoom(rng.standard_normal((64, 77)), (2048 / 64, 2448 / 77), order=1)
        frames.append(np.clip(flat * (1 + 0.05 * field), 0, 4095).astype(np.uint16))
    return optics, calibrate(white, optics), flat, np.stack(frames), white


#: Fixtures that open Qt windows: they need a display (pytest-xvfb starts Xvfb where it exists).
_GUI_FIXTURES = {"qtbot", "qapp", "make_napari_viewer", "make_napari_viewer_proxy"}


def _display() -> bool:
    """A screen Qt can open windows on: a real one, Xvfb (started by pytest-xvfb), or offscreen."""
    return bool(
        os.environ.get("DISPLAY")
        or os.environ.get("WAYLAND_DISPLAY")
        or os.environ.get("QT_QPA_PLATFORM") in ("offscreen", "minimal")
    )


def _qt_can_open_windows() -> str:
    """'' where a Qt application starts on this display, else why not (tried in a child process:
    Qt aborts the process when its platform plugin cannot load, e.g. without the xcb libraries)."""
    import subprocess
    import sys

    code = "from qtpy.QtWidgets import QApplication; QApplication([])"
    try:
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"Qt did not start ({type(e).__name__})"
    if run.returncode == 0:
        return ""
    last = (run.stderr.strip().splitlines() or ["no message"])[-1]
    return (
        f"Qt cannot open a window here ({last[:120]}); install its libraries, e.g. apt install libxcb-icccm4 "
        "libxcb-image0 libxcb-keysyms1 libxcb-randr0 libxcb-render-util0 libxcb-xinerama0 libxkbcommon-x11-0"
    )


#: The slow modules, the longest first (measured in the slow run on 2 cores, both busy: 657, 220, 207,
#: 188, 122 s): CI's slow run (``--dist loadfile --no-loadscope-reorder``: one worker per module, so a
#: simulated case is made once) starts them first on its workers, so that the workers end together.
SLOWEST_FIRST = (
    "test_accuracy_stacked.py",
    "test_accuracy_strong_bead.py",
    "test_accuracy_cell.py",
    "test_accuracy_depth.py",
    "test_accuracy_pmma.py",
)


def _slowest_first(items) -> None:
    """The modules of :data:`SLOWEST_FIRST` first, in its order (the others keep theirs)."""
    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


def pytest_collection_modifyitems(config, items):
    """Skip the napari GUI tests, with the reason, where no display can be made or Qt cannot start
    on it (Qt would abort the whole run); the slowest modules first."""
    _slowest_first(items)
    gui = [item for item in items if _GUI_FIXTURES & set(getattr(item, "fixturenames", ()))]
    if not gui:
        return
    why = "" if not _display() else _qt_can_open_windows()
    if _display() and not why:
        return
    reason = why or "no display for the napari GUI tests: install Xvfb (apt install xvfb) to run them"
    skip = pytest.mark.skip(reason=reason)
    for item in gui:
        item.add_marker(skip)


@pytest.fixture(autouse=True, scope="session")
def _own_settings_folder(tmp_path_factory):
    """The napari dock remembers its settings between sessions: keep the tests' out of the home folder."""
    os.environ["NAPARI_SSDPC_CONFIG"] = str(tmp_path_factory.mktemp("ssdpc-config"))


@pytest.fixture(autouse=True)
def _gui_garbage_collected_here(request):
    """After a GUI test, collect its garbage (viewers, widgets, layers) on the main thread. Left to
    the collector, it may run in whatever thread allocates next (zarr's I/O loop, a Dask worker),
    and Qt objects must not be destroyed there."""
    yield
    if _GUI_FIXTURES & set(request.fixturenames):
        gc.collect()
