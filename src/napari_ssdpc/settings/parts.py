"""The instrument's parts as settings models: objective, microlens array, sensor."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from napari_ssdpc.settings.base import SettingsModel, bounded

__all__ = ["MLA", "PART_KEYS", "Objective", "Sensor"]


class Objective(SettingsModel):
    """The microscope objective."""

    magnification: float = bounded(..., 1.0, 200.0, "lateral magnification with its tube lens (x)")
    na: float = bounded(..., 0.01, 1.7, "numerical aperture")
    tube_lens_mm: float = bounded(..., 20.0, 1000.0, "tube-lens focal length, mm (160-200 mm is usual)")


class MLA(SettingsModel):
    """The microlens array, in a plane conjugate to the objective's back focal plane."""

    pitch_um: float = bounded(..., 10.0, 10000.0, "lenslet pitch, µm (500 µm is 0.5 mm)")
    focal_length_mm: float = bounded(..., 0.1, 500.0, "lenslet focal length, mm")
    lenslet_radius_um: float = bounded(..., 5.0, 10000.0, "lenslet aperture radius, µm")
    grid: Literal["square", "hex"] = Field("square", description="lattice of the array: square or hex")

    @model_validator(mode="after")
    def _radius_fits(self) -> MLA:
        if self.lenslet_radius_um > 0.5 * self.pitch_um * 1.0001:
            raise ValueError(
                f"mla.lenslet_radius_um {self.lenslet_radius_um} exceeds half the pitch {self.pitch_um} µm; "
                "check mla.lenslet_radius_um"
            )
        return self


class Sensor(SettingsModel):
    """The camera."""

    pixel_um: float = bounded(..., 0.5, 50.0, "pixel pitch, µm")
    width_px: int = bounded(..., 16, 100000, "frame width, px")
    height_px: int = bounded(..., 16, 100000, "frame height, px")


#: Flat attribute names of :class:`Optics` that live in a part (for ``Optics.replace``).
PART_KEYS = {
    "magnification": ("objective", "magnification"),
    "na": ("objective", "na"),
    "tube_lens_mm": ("objective", "tube_lens_mm"),
    "pitch_um": ("mla", "pitch_um"),
    "mla_focal_length_mm": ("mla", "focal_length_mm"),
    "lenslet_radius_um": ("mla", "lenslet_radius_um"),
    "grid": ("mla", "grid"),
    "pixel_um": ("sensor", "pixel_um"),
    "width_px": ("sensor", "width_px"),
    "height_px": ("sensor", "height_px"),
}
