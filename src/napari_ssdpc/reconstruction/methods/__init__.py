"""The phase methods: one interface (:class:`~.base.PhaseMethod`), one registry (:data:`METHODS`).

A method turns one frame's flat-fielded views (and, for the paper's route, the directional stacks)
into the phase of every slab. Every method is built once from the optics, the calibration's views
and its own section of the reconstruction settings, then solves frame after frame, optionally
from a warm start (the previous frame's solution), with progress and cancel, and reports what it
did. The CLI choices, the napari method list, the benchmark rows and the docs table come from
:data:`METHODS`.

Adding a method is one new module in this package (a :class:`~.base.PhaseMethod` subclass), its
settings section in :mod:`napari_ssdpc.settings.reconstruction` and one line here
(docs/architecture.md has a worked example).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module
from typing import TYPE_CHECKING

from napari_ssdpc.errors import SsdpcError

if TYPE_CHECKING:
    from napari_ssdpc.reconstruction.methods.base import PhaseMethod

__all__ = ["METHODS", "MethodEntry", "method_class"]


@dataclass(frozen=True)
class MethodEntry:
    """A registered phase method.

    Attributes
    ----------
    module : str
        The module that defines it (imported on first use, so listing the methods stays light).
    cls : str
        Its :class:`~.base.PhaseMethod` subclass.
    summary : str
        One line for the CLI help, the napari list and the docs table.
    slow : bool
        Minutes a frame rather than seconds: ``ssdpc bench --quick`` leaves it out.
    """

    module: str
    cls: str
    summary: str
    slow: bool = False


_HERE = __name__
#: Name -> entry, in the order the CLI and napari list them (the settings' ``method`` choices).
METHODS: dict[str, MethodEntry] = {
    "tv": MethodEntry(
        f"{_HERE}.tv",
        "TvMethod",
        "all views' defocused WOTFs inverted with total variation, the sign of Δn, a bound and the field stop",
    ),
    "wotf": MethodEntry(f"{_HERE}.wotf", "WotfMethod", "3D Tikhonov inversion of all views' WOTFs: linear, fastest"),
    "rl": MethodEntry(
        f"{_HERE}.rl",
        "RlMethod",
        "the paper's route: Richardson-Lucy stacks per half, DPC, Tikhonov phase per slice (Eq. 7)",
    ),
    "multislice": MethodEntry(
        f"{_HERE}.multislice",
        "MultisliceMethod",
        "tv refined with a multislice model of the views (refraction, multiple scattering): strong objects",
        slow=True,
    ),
}


def method_class(name: str) -> type[PhaseMethod]:
    """The class of a registered method.

    Parameters
    ----------
    name : str
        A key of :data:`METHODS`.

    Returns
    -------
    type of PhaseMethod
    """
    if name not in METHODS:
        raise SsdpcError(f"unknown phase method '{name}'; use one of {', '.join(METHODS)}")
    entry = METHODS[name]
    cls: type[PhaseMethod] = getattr(import_module(entry.module), entry.cls)
    return cls
