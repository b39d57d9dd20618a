"""What a run writes: the registry of output quantities and the outputs section of a run.

A quantity has a name (the key of ``--save``, of the OME-Zarr image group and of the file
suffix), a unit, a description, a colormap and contrast rule for display, its kind (a (z, y, x)
volume, a (y, x) map, or channels of volumes) and how to take it from a
:class:`~napari_ssdpc.reconstruction.frame_result.Result`. A new quantity is added here, once;
every writer, reader and widget uses this one table. :class:`OutputSettings` is the
``outputs:`` section of a run configuration.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.base import SettingsModel
from napari_ssdpc.settings.lenslets import HALVES, PAIRS

__all__ = [
    "CHANNEL_LABELS",
    "QUANTITIES",
    "SAVE_CHOICES",
    "OutputSettings",
    "Quantity",
    "display",
    "layout",
    "parse_save",
]


@dataclass(frozen=True)
class Quantity:
    """One output quantity.

    Attributes
    ----------
    name : str
        Key ('ri', 'phase', ...): ``--save`` value, OME-Zarr group, file suffix ``OUT_<name>``.
    label : str
        Short display name (napari layer names).
    unit : str
        Physical unit of the values ('' for a dimensionless index or ratio).
    description : str
        One line for metadata and help.
    colormap : str
        napari/matplotlib colormap.
    centred : bool
        Display limits symmetric about the medium index (RI) or zero.
    kind : {'volume', 'map', 'channels'}
        (z, y, x), (y, x) or (c, z, y, x) per frame.
    channels : tuple of str
        Channel names of a 'channels' quantity.
    needs_stacks : bool
        Computed from the Richardson-Lucy stacks (the slower path).
    decimals : int or None
        Decimals a value is shown with (napari's status bar); None: three significant digits.
    """

    name: str
    label: str
    unit: str
    description: str
    colormap: str
    centred: bool
    kind: Literal["volume", "map", "channels"]
    get: Callable[[Any], Any]
    channels: tuple[str, ...] = ()
    needs_stacks: bool = False
    decimals: int | None = None

    @property
    def axes(self) -> str:
        """OME axes of one frame: 'ZYX', 'YX' or 'CZYX'."""
        return {"volume": "ZYX", "map": "YX", "channels": "CZYX"}[self.kind]

    def of(self, result: Any) -> np.ndarray | None:
        """This quantity of a Result, or None when the result does not hold it.

        Parameters
        ----------
        result : Result

        Returns
        -------
        ndarray or None
            Its kind's shape: (z, y, x), (y, x) or (c, z, y, x).
        """
        value = self.get(result)
        if self.kind == "channels":
            if not value:
                return None
            return np.stack([value[c] for c in self.channels])
        return None if value is None else np.asarray(value)

    def channel_keys(self) -> tuple[str, ...]:
        """Keys of a 'channels' quantity's channels ('dpc_ud', 'stack_up', ...); else ``(name,)``."""
        if self.kind != "channels":
            return (self.name,)
        return tuple(f"{self.label.lower()}_{c}" for c in self.channels)

    def file_suffix(self) -> str:
        """'' for the main output (RI), else '_<name>'."""
        return "" if self.name == "ri" else f"_{self.name}"


QUANTITIES: dict[str, Quantity] = {
    q.name: q
    for q in (
        Quantity("ri", "RI", "", "refractive index", "RdBu_r", True, "volume", lambda r: r.ri, decimals=4),
        Quantity(
            "delta_n",
            "Δn",
            "",
            "refractive-index difference to the medium",
            "RdBu_r",
            True,
            "volume",
            lambda r: r.delta_n,
            decimals=4,
        ),
        Quantity("phase", "phase", "rad", "phase per slab, rad", "RdBu_r", True, "volume", lambda r: r.phase),
        Quantity(
            "projected_phase",
            "projected phase",
            "rad",
            "phase summed over z, rad",
            "viridis",
            False,
            "map",
            lambda r: r.projected_phase,
        ),
        Quantity("opd_nm", "OPD", "nm", "optical path difference, nm", "viridis", False, "map", lambda r: r.opd_nm),
        Quantity(
            "dry_mass",
            "dry mass",
            "pg/µm²",
            "dry-mass surface density OPD/α, pg/µm²",
            "magma",
            False,
            "map",
            lambda r: r.dry_mass,
        ),
        Quantity(
            "absorption",
            "absorption",
            "",
            "absorption mu per slab",
            "gray",
            True,
            "volume",
            lambda r: r.absorption,
            needs_stacks=True,
        ),
        Quantity(
            "dpc",
            "DPC",
            "",
            "DPC up-down, left-right (paper Eq. 1)",
            "gray",
            True,
            "channels",
            lambda r: r.dpc,
            channels=tuple(PAIRS),
            needs_stacks=True,
        ),
        Quantity(
            "stacks",
            "stack",
            "",
            "RL intensity stacks up, down, left, right",
            "gray",
            False,
            "channels",
            lambda r: r.stacks,
            channels=HALVES,
            needs_stacks=True,
        ),
    )
}
#: Display names of the channels of DPC (paper Eq. 1) and of the stacks (paper Eq. 5).
CHANNEL_LABELS = {"ud": "up-down", "lr": "left-right", **{h: h for h in HALVES}}
#: What ``--save`` may add to the RI volume, in a fixed order.
SAVE_CHOICES = tuple(n for n in QUANTITIES if n != "ri")


def parse_save(text: str | Iterable[str] | None) -> list[str]:
    """The quantities asked for ('phase,dpc' or a list), checked against the registry.

    Returns
    -------
    list of str
        Names in registry order, without 'ri' (always written).

    Parameters
    ----------
    text : str, iterable of str or None
    """
    names = [s.strip() for s in text.split(",")] if isinstance(text, str) else list(text or [])
    names = [s for s in names if s]
    bad = [s for s in names if s not in SAVE_CHOICES]
    if bad:
        raise SsdpcError(f"--save {','.join(bad)}: unknown output; choose from {','.join(SAVE_CHOICES)}")
    return [n for n in SAVE_CHOICES if n in names]


def layout(n_z: int, shape_yx: tuple[int, int], save: Iterable[str]) -> dict[str, tuple[tuple, str, str]]:
    """{name: (shape per frame, axes, description)} of RI and the quantities asked for.

    Parameters
    ----------
    n_z : int
        Planes.
    shape_yx : (int, int)
        (ny, nx) of a plane.
    save : iterable of str
        Registry names beside RI.

    Returns
    -------
    dict
    """
    out = {}
    for name in ["ri", *parse_save(list(save))]:
        q = QUANTITIES[name]
        shape = {"volume": (n_z, *shape_yx), "map": tuple(shape_yx), "channels": (len(q.channels), n_z, *shape_yx)}
        out[name] = (shape[q.kind], q.axes, q.description)
    return out


def display(key: str) -> tuple[Quantity | None, str]:
    """The quantity behind a layer key and the key's display label.

    Parameters
    ----------
    key : str
        A quantity name ('ri', 'opd_nm', ...) or one channel of a 'channels' quantity
        ('dpc_ud', 'stack_left').

    Returns
    -------
    quantity : Quantity or None
        None for a key that is not in the registry.
    label : str
        Short display name: the quantity's label, with the channel ('DPC up-down', 'stack left').
    """
    if key in QUANTITIES:
        return QUANTITIES[key], QUANTITIES[key].label
    for q in QUANTITIES.values():
        for c, k in zip(q.channels, q.channel_keys()):
            if k == key:
                return q, f"{q.label} {CHANNEL_LABELS.get(c, c)}"
    return None, key


class OutputSettings(SettingsModel):
    """What is written beside the RI volume (the ``outputs:`` section of a run configuration)."""

    save: tuple[str, ...] = Field((), description=f"quantities beside RI, from: {', '.join(SAVE_CHOICES)}")
    store_digits: int | None = Field(
        None,
        ge=1,
        le=8,
        description="decimal digits a series store keeps of every value (5: RI within 4e-6, about 6x smaller); "
        "empty: float32 as computed",
    )

    @field_validator("save", mode="before")
    @classmethod
    def _known(cls, value: Any) -> Any:
        if isinstance(value, str):
            value = [s for s in value.split(",")]
        if isinstance(value, list | tuple):
            return tuple(parse_save([str(v) for v in value]))
        return value

    @property
    def needs_stacks(self) -> bool:
        """Whether a saved quantity comes from the Richardson-Lucy stacks."""
        return any(QUANTITIES[s].needs_stacks for s in self.save)
