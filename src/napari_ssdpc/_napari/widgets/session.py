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

from napari_ssdpc._napari.placement import follow_optics
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import ReconstructionSettings

__all__ = [
    "TV_KEYS",
    "Session",
    "build_reconstructor",
    "calibration_of",
    "real_viewer",
    "remembered_settings_path",
    "session_for",
]


class Session:
    """State shared by the widgets of one viewer: the optics and the last built operators."""

    optics_changed = Signal(object)  # any edit of the optics
    optics_loaded = Signal(object)  # a new optics file/preset: widgets reset their defaults
    settings_loaded = Signal(object)  # a settings file: widgets show its ReconstructionSettings
    operators_built = Signal(object)

    def __init__(self):
        self.optics = Optics.paper()
        self.base = ReconstructionSettings()  # what no widget shows (dn_max, device, ...) and the defaults
        self.built = None  # (spec, Reconstructor)
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

    def set_optics(self, optics: Optics, loaded: bool = False):
        """Make ``optics`` the session's.

        Parameters
        ----------
        optics : Optics
        loaded : bool
            A new file or preset (the widgets reset their defaults), not an edit.
        """
        self.optics = optics
        self.optics_changed.emit(optics)
        if loaded:
            self.optics_loaded.emit(optics)

    def spec(self) -> dict:
        """Everything a Reconstructor is built from: the Operators widget's z range, dz, model,
        method and calibration, and the Reconstruct widget's flat frame and α."""
        rec = self.base.to_dict()
        spec = {
            "optics": self.optics,
            "calibration": None,
            "z": (float(rec["z_min_um"]), float(rec["z_max_um"])),
            "dz": float(rec["dz_um"]),
            "model": rec["model"],
            "method": rec["method"],
            "stacks": False,  # RL stacks only when DPC, stacks, absorption or the PSF are asked for
            "alpha": rec["tikhonov_alpha"],
            "tv": {k: rec[k] for k in TV_KEYS},
            "flat": None,
        }
        for w in self._widgets():
            given = w.operator_settings()
            spec.update({**given, "tv": {**spec["tv"], **given.get("tv", {})}})
        return spec

    def _widgets(self):
        refs = (self.operators_widget, self.reconstruct_widget)
        return [w for w in (r() if r is not None else None for r in refs) if w is not None]

    def settings(self) -> ReconstructionSettings:
        """The reconstruction settings the widgets show now, as the CLI reads them.

        Returns
        -------
        ReconstructionSettings
            z range, method and its parameters from the widgets; the rest from the last loaded file.
        """
        spec = self.spec()
        values = {
            **self.base.to_dict(),
            **spec["tv"],
            "z_min_um": spec["z"][0],
            "z_max_um": spec["z"][1],
            "dz_um": spec["dz"],
            "method": spec["method"],
            "model": spec["model"],
            "tikhonov_alpha": spec["alpha"],
        }
        for w in self._widgets():
            values.update(getattr(w, "run_settings", dict)())
        return ReconstructionSettings.from_dict(values, source="the dock's settings")

    def run_config(self) -> RunConfig:
        """The optics and the reconstruction settings: what ``ssdpc reconstruct --config`` reads."""
        return RunConfig(optics=self.optics, reconstruction=self.settings())

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
            self.run_config().to_yaml(path)
        except (SsdpcError, OSError):
            pass

    def matching(self, spec):
        """The built Reconstructor if it was made from exactly ``spec``, else None.

        Parameters
        ----------
        spec : dict
            As :meth:`spec` returns it.

        Returns
        -------
        Reconstructor or None
        """
        if self.built is None:
            return None
        old, rec = self.built
        same = all((old[k] is spec[k]) if k in ("optics", "calibration", "flat") else old[k] == spec[k] for k in spec)
        return rec if same else None


#: Settings a widget hands to the 'tv' solver (a subset of ReconstructionSettings).
TV_KEYS = ("sign", "tv_lambda", "tv_iterations", "dn_max", "refraction_increment_um3_pg")


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
        weakref.finalize(viewer, _SESSIONS.pop, key, None)  # free the operators with the viewer
    return session


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
    from napari_ssdpc.calibration.calibrate import Calibration

    info = layer.metadata.get("ssdpc", {})
    if "_object" not in info:
        info["_object"] = Calibration.from_dict(info["calibration"], source=f"layer '{layer.name}'")
    return info["_object"]


def build_reconstructor(spec, progress=None):
    """A core Reconstructor from a session spec (called in the worker thread).

    Parameters
    ----------
    spec : dict
        As Session.spec returns it.
    progress : callable, optional

    Returns
    -------
    Reconstructor
    """
    from napari_ssdpc.reconstruction.pipeline import Reconstructor

    if spec["calibration"] is None:
        raise SsdpcError("no calibration: run Calibrate on a white frame, or open a calibration JSON")
    flat = None if spec["flat"] is None else np.asarray(spec["flat"])
    return Reconstructor(
        spec["optics"],
        spec["calibration"],
        ReconstructionSettings.from_dict(spec["tv"], source="TV settings"),
        z=spec["z"],
        dz=spec["dz"],
        model=spec["model"],
        method=spec["method"],
        stacks=spec["stacks"],
        alpha=spec["alpha"],
        flat=flat,
        progress=progress,
    )
