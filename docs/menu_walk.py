"""A user's walk through napari's real menus and the dock's buttons, timed, optionally beside busy work.

Plugins › ssDPC light-field phase › ssDPC, File › Open Sample › PMMA bead, the Calibrate button, the
Reconstruct button with the dock's defaults (161 planes), a profile line, a step of the z slider,
a movie, File › Open Sample › Moving sample, then File › Exit. A 50 ms timer on napari's event loop
gives the longest time the GUI did not answer in each step (and, first, while napari alone adds three
1024 x 1024 images: what the display and the load cost napari itself); the walk also gives the time from the
Reconstruct button to the first RI layer and to the answer, and napari's exit status.

    xvfb-run -a -s "-screen 0 1280x800x24" python docs/menu_walk.py [--busy N] [--json OUT.json]

``--busy N`` starts N processes that keep a core busy each for the whole walk (a workstation that
also acquires or runs another analysis). docs/napari.md has the results.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BEAT_MS = 50


def _action(menu_bar, *path: str):
    """The QAction at the end of a menu path (each name a prefix of the entry's text)."""
    actions = menu_bar.actions()
    for name in path:
        found = [a for a in actions if a.text().replace("&", "").startswith(name)]
        if not found:
            raise SystemExit(f"no menu entry {name!r} in {[a.text() for a in actions]}")
        action = found[0]
        actions = action.menu().actions() if action.menu() is not None else []
    return action


def _tabs(widget):
    """The ssDPC dock's tabs inside a dock widget (its scroll area's content), or None."""
    for w in (widget, getattr(widget, "widget", lambda: None)()):
        if w is not None and hasattr(w, "tabs"):
            return w.tabs
    return None


def walk(out: dict) -> None:
    import napari
    import numpy as np
    from qtpy.QtCore import QTimer
    from qtpy.QtWidgets import QApplication

    from napari_ssdpc._napari import turns

    viewer = napari.Viewer()
    app = QApplication.instance()
    beats, step = [], ["start"]
    timer = QTimer()
    timer.timeout.connect(lambda: beats.append((time.perf_counter(), step[0])))
    timer.start(BEAT_MS)
    bar = viewer.window._qt_window.menuBar()

    def settle(runner=None, seconds: float = 1.0, timeout_s: float = 1800.0) -> None:
        t0 = time.perf_counter()
        while (runner is not None and runner.worker is not None) or turns.pending():
            app.processEvents()
            time.sleep(0.005)
            if time.perf_counter() - t0 > timeout_s:
                raise SystemExit(f"{step[0]}: not done in {timeout_s} s")
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            app.processEvents()
            time.sleep(0.005)

    def do(name: str, action, runner=None) -> float:
        """The step; returns when its job (if any) ended."""
        step[0] = name
        QTimer.singleShot(0, action)  # from the event loop, as a click
        settle(seconds=0.2)
        if runner is not None:
            settle(runner, seconds=0.0)
        ended = time.perf_counter()
        settle()
        return ended

    settle(seconds=2.0)
    step[0] = "napari alone: three 1024 x 1024 images"  # what the display and the load cost napari itself
    for i in range(3):
        viewer.add_image(np.zeros((1024, 1024), np.uint16), name=f"reference {i}")
    settle()
    for i in range(3):
        viewer.layers.remove(f"reference {i}")
    settle()
    do("Plugins › ssDPC", _action(bar, "Plugins", "ssDPC light-field phase", "ssDPC").trigger)
    [tabs] = [_tabs(w) for w in viewer.window.dock_widgets.values() if _tabs(w)]
    sample = _action(bar, "File", "Open Sample", "ssDPC light-field phase", "PMMA bead")
    do("File › Open Sample › PMMA bead", sample.trigger)
    do("Calibrate", tabs["Calibrate"].run_button.native.click, tabs["Calibrate"].runner)
    rec = tabs["Reconstruct"]
    arrived = {}
    viewer.layers.events.inserted.connect(
        lambda e: e.value.name == "PMMA bead RI" and arrived.setdefault("first", time.perf_counter())
    )
    pressed = time.perf_counter()
    ended = do("Reconstruct (the dock's defaults)", rec.run_button.native.click, rec.runner)
    out["first RI layer after the press, s"] = round(arrived["first"] - pressed, 1)
    out["answer after the press, s"] = round(ended - pressed, 1)
    out["planes"] = int(viewer.layers["PMMA bead RI"].data.shape[0])
    profile = tabs["Profile"]

    def draw_line():
        lines = profile.new_line_layer()
        lines.add_lines(np.array([[80.0, 72.0, 20.0], [80.0, 72.0, 125.0]]))  # across the bead, voxels

    do("Profile: a line", draw_line)
    do("z slider: one step", lambda: viewer.dims.set_current_step(0, viewer.dims.current_step[0] + 1))
    movie = tabs["Movie"]
    movie.seconds.value, movie.fps.value = 2, 10
    movie.path.value = Path(tempfile.mkdtemp()) / "bead.gif"
    do("Movie", movie.run_button.native.click, movie.runner)
    moving = _action(bar, "File", "Open Sample", "ssDPC light-field phase", "Moving sample")
    do("File › Open Sample › Moving sample", moving.trigger)
    timer.stop()
    gaps: dict = {}
    for (t0, _), (t1, name) in zip(beats, beats[1:]):
        gaps[name] = max(gaps.get(name, 0.0), t1 - t0)
    out["longest stall per step, s"] = {k: round(v, 2) for k, v in gaps.items()}
    out["window, px"] = [viewer.window._qt_window.width(), viewer.window._qt_window.height()]
    QTimer.singleShot(500, _confirm)  # napari asks before it quits: Quit, as a user does
    _action(bar, "File", "Exit").trigger()


def _confirm() -> None:
    from qtpy.QtWidgets import QApplication

    dialog = QApplication.activeModalWidget()
    if dialog is not None:
        dialog.accept()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--busy", type=int, default=0, help="processes keeping a core busy each (default 0)")
    p.add_argument("--json", default=None, help="write the results here too")
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:  # the walk itself, in its own process: its exit status is napari's
        out: dict = {}
        try:
            walk(out)
        finally:
            Path(args.child).write_text(json.dumps(out))
        return
    spin = f"import os\nwhile os.getppid() == {os.getpid()}: pass"
    spinners = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(args.busy)]
    try:
        time.sleep(1.0 if spinners else 0.0)
        with tempfile.TemporaryDirectory() as tmp:
            result = Path(tmp) / "walk.json"
            t0 = time.perf_counter()
            rc = subprocess.run([sys.executable, __file__, "--child", str(result)]).returncode
            out = json.loads(result.read_text()) if result.exists() else {}
        out.update(
            exit_status=rc,
            walk_s=round(time.perf_counter() - t0, 1),
            busy_processes=args.busy,
            load_average=round(os.getloadavg()[0], 1),
            cores=os.cpu_count(),
        )
    finally:
        for s in spinners:
            s.kill()
    print(json.dumps(out, indent=1, ensure_ascii=False))
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1, ensure_ascii=False))


if __name__ == "__main__":
    main()
