"""One Session per viewer: the optics and the built operators that every dock widget shares.

napari hands each dock widget opened from the Plugins menu its own proxy of the viewer; the
session is keyed on the real viewer behind it, so all widgets (and the ssDPC dock) see one model.
"""

from __future__ import annotations

import os
import weakref
from pathlib import Path

import numpy as np
from psygnal import Signal

from napari_ssdpc._napari.placement import follow_optics, follow_results
from napari_ssdpc._napari.preferences import prefer_own_readers
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.pipeline.job import Job
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.outputs import OutputSettings
from napari_ssdpc.settings.reconstruction import ReconstructionSettings, merge_settings

__all__ = [
    "Session",
    "calibration_of",
    "real_viewer",
    "remembered_settings_path",
    "session_for",
]


class Session:
    """State shared by the widgets of one viewer: the optics and the last built operators."""

    optics_changed = Signal(object)  # any edit of the optics
    optics_loaded = Signal(object)  # a new optics file/preset: widgets reset their defaults
    optics_adopted = Signal(object)  # the optics a frame brought: shown, the other settings kept
    settings_loaded = Signal(object)  # a settings file: widgets show its ReconstructionSettings
    operators_built = Signal(object)

    def __init__(self):
        self.optics = Optics.paper()
        self.base = ReconstructionSettings()  # what no widget shows (dn_max, device, ...) and the defaults
        self.built = None  # (Job, Reconstructor)
        self.operators_widget = None  # weak references, set by the widgets
        self.reconstruct_widget = None

    def use(self, role: str, widget) -> None:
        """Make ``widget`` the one whose values count for ``role`` ('operators_widget' or
        'reconstruct_widget'): the newest, or the one edited last when the dock and a separate
        widget of the same kind are both open.

        Parameters
        ----------
        role : str
        widget : OperatorsWidget or ReconstructWidget
        """
        setattr(self, role, weakref.ref(widget))

    def set_optics(self, optics: Optics, loaded: bool = False, adopted: bool = False):
        """Make ``optics`` the session's.

        Parameters
        ----------
        optics : Optics
        loaded : bool
            A new file or preset (the widgets reset their defaults), not an edit.
        adopted : bool
            The optics a frame brought (the sample data): the Optics tab shows them, the z range,
            method and α the user set stay.
        """
        self.optics = optics
        self.optics_changed.emit(optics)
        if loaded:
            self.optics_loaded.emit(optics)
        elif adopted:
            self.optics_adopted.emit(optics)

    def _widgets(self):
        refs = (self.operators_widget, self.reconstruct_widget)
        return [w for w in (r() if r is not None else None for r in refs) if w is not None]

    def settings(self) -> ReconstructionSettings:
        """The reconstruction settings the widgets show now, as the CLI reads them.

        Each widget gives the keys it shows (``settings_changes``: top-level keys and method
        sections; the section ``'*'`` is the chosen method's); the rest comes from the last loaded
        file. Validated once, here.

        Returns
        -------
        ReconstructionSettings
        """
        changes: dict = {}
        for w in self._widgets():  # every widget's keys first: '*' is the method the dock ends with
            for key, value in w.settings_changes().items():
                changes[key] = {**changes.get(key, {}), **value} if isinstance(value, dict) else value
        data = merge_settings(self.base.to_dict(), changes)
        return ReconstructionSettings.from_dict(data, source="the dock's settings")

    def config(self, save=()) -> RunConfig:
        """The optics, the reconstruction settings and the outputs: what ``ssdpc reconstruct --config`` reads.

        Parameters
        ----------
        save : iterable of str
            Quantities beside RI.

        Returns
        -------
        RunConfig
        """
        return RunConfig(
            optics=self.optics, reconstruction=self.settings(), outputs=OutputSettings.from_dict({"save": list(save)})
        )

    def job(self, save=()) -> Job:
        """The job the widgets describe: run configuration, calibration, flat, stacks.

        Parameters
        ----------
        save : iterable of str
            Quantities beside RI.

        Returns
        -------
        Job
        """
        inputs: dict = {"calibration": None, "flat": None, "stacks": False}
        for w in self._widgets():
            inputs.update(w.inputs())
        if inputs["calibration"] is None:
            raise SsdpcError("no calibration: run Calibrate on a white frame, or open a calibration JSON")
        flat = None if inputs["flat"] is None else np.asarray(inputs["flat"])
        return Job(self.config(save), inputs["calibration"], flat, stacks=bool(inputs["stacks"]))

    def load_config(self, config: RunConfig) -> None:
        """Show a run configuration in every widget (optics first, then the settings).

        Parameters
        ----------
        config : RunConfig
            As read by :meth:`RunConfig.from_yaml`.
        """
        self.base = config.reconstruction
        self.set_optics(config.optics, loaded=True)
        self.settings_loaded.emit(config.reconstruction)

    def remember(self) -> None:
        """Keep the settings for the next napari session (a failed write is not an error)."""
        path = remembered_settings_path()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.config().to_yaml(path)
        except (SsdpcError, OSError):
            pass

    def matching(self, job: Job):
        """The built Reconstructor if it serves ``job`` (the same calibration and flat, operators
        of the same settings; runtime settings such as iterations are taken over), else None.

        Parameters
        ----------
        job : Job

        Returns
        -------
        Reconstructor or None
        """
        if self.built is None:
            return None
        old, rec = self.built
        same_inputs = old.calibration is job.calibration and _same_array(old.flat, job.flat)
        if same_inputs and (rec.stacks is not None or not job.stacks) and rec.adopt(job.config):
            return rec
        return None


def _same_array(a, b) -> bool:
    """The same frame: both None, or equal arrays (a layer's data may be copied, not changed)."""
    if a is None or b is None:
        return a is b
    return a is b or (a.shape == b.shape and np.array_equal(a, b))


def remembered_settings_path() -> Path:
    """Where the dock keeps the last settings: ``$NAPARI_SSDPC_CONFIG`` or ~/.config/napari-ssdpc."""
    root = os.environ.get("NAPARI_SSDPC_CONFIG") or Path.home() / ".config" / "napari-ssdpc"
    return Path(root) / "last-settings.yaml"


_SESSIONS: dict[int, tuple] = {}


def real_viewer(viewer):
    """The viewer behind napari's plugin proxy.

    napari hands every dock widget opened from the Plugins menu its own ``PublicOnlyProxy`` of
    the viewer; keyed on the proxy, each widget would get its own session and never see the
    calibration or the optics another one set.

    Parameters
    ----------
    viewer : napari.Viewer or its proxy

    Returns
    -------
    napari.Viewer
    """
    while hasattr(type(viewer), "__wrapped__") or type(viewer).__name__ == "PublicOnlyProxy":
        inner = getattr(viewer, "__wrapped__", None)
        if inner is None or inner is viewer:
            break
        viewer = inner
    return viewer


def session_for(viewer) -> Session:
    """The Session of ``viewer`` (one per real viewer, created on first use; proxies share it).

    Parameters
    ----------
    viewer : napari.Viewer or its proxy

    Returns
    -------
    Session
    """
    viewer = real_viewer(viewer)
    key = id(viewer)
    ref, session = _SESSIONS.get(key, (None, None))
    if ref is None or ref() is not viewer:
        session = Session()
        _SESSIONS[key] = (weakref.ref(viewer), session)
        follow_optics(viewer, session)  # frames shown in µm follow edits of the optics
        adopt_frame_optics(viewer, session)  # the sample brings its own optics
        follow_results(viewer)  # the first result is brought into view, however it arrives
        prefer_own_readers()  # the plugin's own files open without napari's "Choose reader"
        weakref.finalize(viewer, _SESSIONS.pop, key, None)  # free the operators with the viewer
    return session


def adopt_frame_optics(viewer, session: Session) -> None:
    """Raw frames that carry their optics (the sample data) make them the session's when they arrive.

    The sample's frames are only right with the optics they were simulated with (the bead: condenser
    NA 0.3; the moving sample: water): the Optics tab shows them; the z range, method and α the
    user set stay (as with "From selected layer"). Layers already in the viewer count too (the
    sample opened before the dock). Nothing happens when the optics are already the session's.

    Parameters
    ----------
    viewer : napari.Viewer
    session : Session
    """
    from napari_ssdpc._napari import notify

    def adopt(layer) -> None:
        meta = layer.metadata.get("ssdpc", {})
        if meta.get("kind") != "raw" or not meta.get("optics"):
            return
        try:
            optics = Optics.from_dict(meta["optics"], source=f"layer '{layer.name}'")
        except SsdpcError as e:
            notify.warning(f"{e}; the optics stay as they were")
            return
        if optics != session.optics:
            session.set_optics(optics, adopted=True)
            notify.info(
                f"optics of '{layer.name}' adopted: {optics.name} (condenser NA {optics.condenser_na:g}, "
                f"medium n {optics.medium_index:g})"
            )

    viewer.layers.events.inserted.connect(lambda e: adopt(e.value))
    for layer in viewer.layers:
        adopt(layer)


def calibration_of(layer):
    """The Calibration stored in a calibration layer's metadata (cached on the metadata dict).

    Parameters
    ----------
    layer : napari layer
        Made by Calibrate or read from a calibration JSON.

    Returns
    -------
    Calibration
    """
    from napari_ssdpc.calibration import Calibration

    info = layer.metadata.get("ssdpc", {})
    if "_object" not in info:
        info["_object"] = Calibration.from_dict(info["calibration"], source=f"layer '{layer.name}'")
    return info["_object"]
