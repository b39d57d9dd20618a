"""The ssDPC dock: the whole workflow in one dock, as tabs (optics, calibrate, method, reconstruct,
slices, profile, movie), with the settings file the command line reads.

It is the plugin's one entry in napari's Plugins menu. Each tab is a widget of its own (scripts can
make them directly, e.g. ``CalibrateWidget(viewer)``); all of them share the viewer's
:class:`~napari_ssdpc._napari.widgets.session.Session`, so the dock and any separate widget always
agree. The dock asks for :data:`DOCK_WIDTH_PX` and its tabs scroll (down, and sideways when dragged
narrower), so napari's first window (1089 x 633 px on a 1280 x 800 screen) keeps a 492 px wide canvas
beside it. The settings of the last run are remembered for the next napari session.
"""

from __future__ import annotations

from pathlib import Path

from qtpy.QtCore import QSize, QTimer
from qtpy.QtWidgets import QFileDialog, QHBoxLayout, QMenu, QPushButton, QTabWidget, QVBoxLayout, QWidget

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.placement import place_frames
from napari_ssdpc._napari.profiles import ProfileWidget
from napari_ssdpc._napari.widgets.calibrate import CalibrateWidget
from napari_ssdpc._napari.widgets.common import scrolling
from napari_ssdpc._napari.widgets.movie import MovieWidget
from napari_ssdpc._napari.widgets.operators import OperatorsWidget
from napari_ssdpc._napari.widgets.optics import OpticsWidget
from napari_ssdpc._napari.widgets.plot import preload_matplotlib
from napari_ssdpc._napari.widgets.reconstruct import ReconstructWidget
from napari_ssdpc._napari.widgets.session import remembered_settings_path, session_for
from napari_ssdpc._napari.widgets.slices import SlicesWidget
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.config import RunConfig

__all__ = ["DOCK_MIN_WIDTH_PX", "DOCK_WIDTH_PX", "SsdpcDock"]

#: Width the dock asks for: room for a label and a spin box (napari's first window keeps a 492 px canvas).
DOCK_WIDTH_PX = 300
#: Narrowest the dock can be dragged: a tab wider than this scrolls sideways.
DOCK_MIN_WIDTH_PX = 240
#: The dock's tabs: (title, widget class).
TABS = (
    ("Optics", OpticsWidget),
    ("Calibrate", CalibrateWidget),
    ("Method", OperatorsWidget),
    ("Reconstruct", ReconstructWidget),
    ("Slices", SlicesWidget),
    ("Profile", ProfileWidget),
    ("Movie", MovieWidget),
)


class SsdpcDock(QWidget):
    """One dock for the workflow: optics → calibrate → method → reconstruct → profile.

    Parameters
    ----------
    napari_viewer : napari.Viewer
        The viewer (or napari's proxy of it); the dock uses the viewer's shared session.

    Attributes
    ----------
    tabs : dict
        {title: widget} of the workflow steps ("Optics", "Calibrate", ...).
    """

    def __init__(self, napari_viewer):
        super().__init__()
        # the Slices and Profile plots: matplotlib imported beside the GUI thread once the dock is up
        QTimer.singleShot(0, preload_matplotlib)
        self.viewer = napari_viewer
        self.session = session_for(napari_viewer)
        self.tabs = {title: cls(napari_viewer) for title, cls in TABS}
        self.tab_widget = QTabWidget()
        self.tab_widget.setUsesScrollButtons(True)
        self.tab_widget.setTabPosition(QTabWidget.TabPosition.West)  # all seven tabs in view, in the workflow order
        for title, w in self.tabs.items():  # the magicgui steps scroll themselves
            page = w.root_native_widget if hasattr(w, "native") else scrolling(w)
            page.setMinimumWidth(DOCK_MIN_WIDTH_PX - 10)  # narrower than its content: it scrolls sideways
            self.tab_widget.addTab(page, title)
        buttons = QHBoxLayout()
        open_raw = QPushButton("Open raw…")
        open_raw.setToolTip("open a raw light-field frame or (t, y, x) series (TIFF)")
        open_raw.clicked.connect(self._open_raw_dialog)
        settings = QPushButton("Settings")  # a menu: the dock stays narrow
        settings.setToolTip("load or save the optics and reconstruction settings (ssdpc reconstruct --config YAML)")
        menu = QMenu(settings)
        menu.addAction("Load settings…", self._load_dialog)
        menu.addAction("Save settings…", self._save_dialog)
        settings.setMenu(menu)
        for b in (open_raw, settings):
            buttons.addWidget(b)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addLayout(buttons)
        layout.addWidget(self.tab_widget)
        self.setMinimumWidth(DOCK_MIN_WIDTH_PX)
        self._restore()

    def sizeHint(self) -> QSize:
        """The width napari gives the dock when it opens: :data:`DOCK_WIDTH_PX` (the tabs scroll)."""
        return QSize(DOCK_WIDTH_PX, super().sizeHint().height())

    # ------------------------------------------------------------------ settings
    def save_settings(self, path) -> Path | None:
        """Write the optics and reconstruction settings as a run configuration YAML.

        Parameters
        ----------
        path : str or Path
            The YAML file (``ssdpc reconstruct --config`` reads it).

        Returns
        -------
        Path or None
            The file written; None when the settings are invalid or the file cannot be written
            (the message is shown).
        """
        try:
            return self.session.config().to_yaml(path)
        except SsdpcError as e:
            notify.error(e)
        except OSError as e:
            notify.error(f"could not write {path}: {e.strerror}; choose a writable folder")
        return None

    def load_settings(self, path) -> bool:
        """Read a run configuration (or an optics YAML) into every widget.

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        bool
            Whether it was read (otherwise the one-line reason is shown).
        """
        try:
            self.session.load_config(RunConfig.from_yaml(path))
        except SsdpcError as e:
            notify.error(e)
            return False
        return True

    def open_raw(self, path) -> list:
        """Add a raw frame or series with this plugin's reader (whatever the file's name).

        Parameters
        ----------
        path : str or Path
            A TIFF or OME-TIFF light-field frame (y, x) or series (t, y, x).

        Returns
        -------
        list of napari layers
        """
        from napari_ssdpc._napari.reader import get_raw_reader

        reader = get_raw_reader(str(path))
        if reader is None:
            notify.error(f"{path}: not a light-field frame (a 2D or (t, y, x) grey-level TIFF); choose another file")
            return []
        added = [getattr(self.viewer, f"add_{kind}")(data, **kwargs) for data, kwargs, kind in reader(str(path))]
        place_frames(self.viewer, self.session.optics)  # in the volume's µm, beside the results
        return added

    def _restore(self) -> None:
        """The last session's settings, if any (silently skipped when unreadable)."""
        path = remembered_settings_path()
        if path.is_file():
            try:
                self.session.load_config(RunConfig.from_yaml(path))
            except SsdpcError:
                pass

    def _save_dialog(self, *_):
        path, _ = QFileDialog.getSaveFileName(self, "Save settings", "ssdpc-settings.yaml", "YAML (*.yaml *.yml)")
        if path:
            self.save_settings(path)

    def _load_dialog(self, *_):
        path, _ = QFileDialog.getOpenFileName(self, "Load settings", "", "YAML (*.yaml *.yml)")
        if path:
            self.load_settings(path)

    def _open_raw_dialog(self, *_):
        path, _ = QFileDialog.getOpenFileName(self, "Open raw frame", "", "TIFF (*.tif *.tiff)")
        if path:
            self.open_raw(path)
