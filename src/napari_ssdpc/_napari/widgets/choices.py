"""Layer choices that follow the data: which layer a combo box offers first, and keeping it there.

magicgui keeps a combo box's current value when the layer list changes, so a widget opened before
the data would stay on whatever layer came first (the white frame as the raw frame, no flat, the
first calibration). :class:`LayerChoice` re-picks the preferred layer every time the layer list
changes, unless the user picked one that is still in the list. The choices callables below order
the layers by preference:

- raw frame: a frame that is neither a white nor a flat frame, the top of the layer list first;
- flat frame: the flat of the same recording as the raw frame (same frame size, the name it shares
  most with), else none;
- calibration frame: a white frame;
- calibration: the newest;
- volume (profile, slices, movie): the newest RI result.
"""

from __future__ import annotations

import os

from magicgui.widgets import ComboBox

__all__ = [
    "LayerChoice",
    "calibration_layer_choices",
    "frame_role",
    "image_layer_choices",
    "result_layer_choices",
    "same_recording_flat",
    "shapes_layer_choices",
]


def frame_role(layer) -> str:
    """'white', 'flat' or 'raw': what a frame layer is, from its metadata or else its name.

    Parameters
    ----------
    layer : napari Image layer

    Returns
    -------
    str
    """
    role = layer.metadata.get("ssdpc", {}).get("frame")
    if role in ("white", "flat", "raw"):
        return role
    name = layer.name.lower()
    return "white" if "white" in name else "flat" if "flat" in name else "raw"


def _frames(viewer, ndims) -> list:
    """Image layers that are frames (not results), the top of the layer list first."""
    from napari.layers import Image

    return [
        lyr
        for lyr in reversed(viewer.layers)
        if isinstance(lyr, Image)
        and lyr.ndim in ndims
        and not lyr.rgb
        and lyr.metadata.get("ssdpc", {}).get("kind") != "result"
    ]


def image_layer_choices(viewer, ndims=(2, 3), allow_none: str | None = None, prefer: str = "raw"):
    """Choices callable for a ComboBox of frame layers: those of the role ``prefer`` first (the
    default choice), then ``allow_none``, then the others; the top of the layer list first.

    Parameters
    ----------
    viewer : napari.Viewer
    ndims : tuple of int
        Layer dimensionalities offered.
    allow_none : str, optional
        Label of a "none" choice.
    prefer : {'raw', 'white', 'flat'}
        The role offered first (see :func:`frame_role`).

    Returns
    -------
    callable
    """

    def choices(_widget=None):
        layers = _frames(viewer, ndims)
        first = [lyr for lyr in layers if frame_role(lyr) == prefer]
        rest = [lyr for lyr in layers if lyr not in first]
        none = [(allow_none, None)] if allow_none else []
        return [(lyr.name, lyr) for lyr in first] + none + [(lyr.name, lyr) for lyr in rest]

    return choices


def same_recording_flat(raw_choice: ComboBox):
    """Preference of a flat-frame ComboBox: the flat of the recording chosen in ``raw_choice``.

    Among the flat frames of the raw frame's size, the one whose name shares the longest start
    with the raw frame's ("PMMA bead" → "PMMA bead flat"); the top of the layer list on a tie;
    None (no flat) when no flat frame fits.

    Parameters
    ----------
    raw_choice : ComboBox
        The raw frame(s) combo box.

    Returns
    -------
    callable
        ``prefer(values) -> layer or None``.
    """

    def prefer(values):
        raw = raw_choice.value
        flats = [v for v in values if v is not None and frame_role(v) == "flat"]
        if raw is not None:
            flats = [f for f in flats if tuple(f.data.shape[-2:]) == tuple(raw.data.shape[-2:])]
        if not flats:
            return None
        if raw is None:
            return flats[0]
        shared = [len(os.path.commonprefix([raw.name.lower(), f.name.lower()])) for f in flats]
        return flats[shared.index(max(shared))]

    return prefer


def calibration_layer_choices(viewer):
    """Choices callable for a ComboBox of calibration (EI circles) layers, the newest first.

    Parameters
    ----------
    viewer : napari.Viewer

    Returns
    -------
    callable
    """

    def choices(_widget=None):
        return [
            (lyr.name, lyr)
            for lyr in reversed(viewer.layers)
            if lyr.metadata.get("ssdpc", {}).get("kind") == "calibration"
            and lyr.metadata["ssdpc"].get("role") == "EI circles"
        ]

    return choices


def shapes_layer_choices(viewer, none: str):
    """Choices callable for a ComboBox of Shapes layers, ``none`` first (the default).

    Parameters
    ----------
    viewer : napari.Viewer
    none : str
        Label of the "none" choice.

    Returns
    -------
    callable
    """
    from napari.layers import Shapes

    def choices(_widget=None):
        return [(none, None)] + [(lyr.name, lyr) for lyr in reversed(viewer.layers) if isinstance(lyr, Shapes)]

    return choices


def result_layer_choices(viewer, min_ndim: int = 3, others: bool = False):
    """Choices callable for a ComboBox of reconstructions: RI results first, the newest first.

    Parameters
    ----------
    viewer : napari.Viewer
    min_ndim : int
        Smallest dimensionality offered (3: volumes and series).
    others : bool
        Also offer the image layers that are not results (after the results).

    Returns
    -------
    callable
    """

    def choices(_widget=None):
        layers = [
            lyr
            for lyr in reversed(viewer.layers)
            if lyr._type_string == "image" and lyr.ndim >= min_ndim and not getattr(lyr, "rgb", False)
        ]
        results = [lyr for lyr in layers if lyr.metadata.get("ssdpc", {}).get("kind") == "result"]
        results.sort(key=lambda lyr: lyr.metadata["ssdpc"].get("quantity") != "ri")  # stable: newest RI first
        rest = [lyr for lyr in layers if lyr not in results] if others else []
        return [(lyr.name, lyr) for lyr in results + rest]

    return choices


class LayerChoice(ComboBox):
    """A ComboBox of layers that follows the data.

    Whenever its choices are reset (layers added, removed, moved or renamed) it shows the preferred
    choice (``prefer``, by default the first offered), unless the user picked a value that is still
    offered. Any value set from outside (a click or a script) counts as the user's pick; a picked
    layer that is removed hands the choice back to the preference.

    Parameters
    ----------
    prefer : callable, optional
        ``prefer(values) -> value``: the preferred one of the offered values.
    **kwargs
        ComboBox arguments (``label``, ``choices`` callable, ``tooltip``).

    Attributes
    ----------
    picked : bool
        Whether the value shown is one the user picked.
    """

    def __init__(self, prefer=None, **kwargs):
        self._prefer = prefer
        self._auto = False
        self.picked = False
        self._picked_value = None
        super().__init__(**kwargs)
        # the Qt signal: magicgui's ``changed`` is silent when a "none" choice (None) is picked
        self.native.currentIndexChanged.connect(self._on_change)
        self.follow()

    def _on_change(self, *_) -> None:
        if not self._auto:
            self.picked, self._picked_value = True, self.value

    def _ordered(self) -> list:
        """The offered values in the order of the choices callable (the combo box keeps the order
        in which items first came, not the callable's)."""
        make = self._default_choices
        if not callable(make):
            return list(self.choices)
        return [c[1] if isinstance(c, tuple) and len(c) == 2 else c for c in make(self)]

    def preferred(self):
        """The preferred one of the offered values (None when nothing is offered)."""
        values = self._ordered()
        if self._prefer is not None:
            return self._prefer(values)
        return values[0] if values else None

    def reset_choices(self, *_) -> None:
        """Offer the current layers, then :meth:`follow` the data."""
        self._auto = True
        try:
            super().reset_choices()
            self.follow()
        finally:
            self._auto = False

    def follow(self) -> None:
        """Show the user's pick while it is offered, else the preferred value."""
        values = list(self.choices)
        if self.picked and any(v is self._picked_value for v in values):
            target = self._picked_value
        else:
            self.picked, self._picked_value = False, None
            target = self.preferred()
        if self.value is not target and any(v is target for v in values):
            auto, self._auto = self._auto, True
            try:
                self.value = target
            finally:
                self._auto = auto
