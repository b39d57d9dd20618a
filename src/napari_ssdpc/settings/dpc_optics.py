"""The optics of a conventional DPC microscope: an LED array or a segmented condenser that lights
one half of the illumination disk per image (the schema of ``ssdpc dpc --optics``, docs/dpc.md).

Conventions as everywhere in this package (docs/conventions.md): object-side lengths in µm, spatial
frequencies in cycles/µm, the illumination as plane waves exp(+i2π w·r) over the source points w,
z > 0 farther from the objective. Each pattern is the half of the illumination disk on the side
of its angle: ``patterns_deg`` gives, for every image of the stack in its order, the direction of
the lit half's outward normal in the w plane, 0° = +x (along columns), 90° = +y (along rows).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from pydantic import Field, model_validator

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.base import SettingsModel, bounded
from napari_ssdpc.settings.files import read_mapping

__all__ = ["DpcOptics"]


class DpcOptics(SettingsModel):
    """A DPC microscope: objective, camera, the illumination disk and its half-disk patterns."""

    name: str = Field("", description="a name for the instrument")
    wavelength_um: float = bounded(..., 0.2, 2.0, "vacuum wavelength, µm (520 nm is 0.52)")
    objective_na: float = bounded(..., 0.01, 1.6, "objective NA")
    magnification: float = bounded(..., 1.0, 200.0, "magnification from the sample to the camera")
    camera_pixel_um: float = bounded(..., 0.5, 50.0, "camera pixel, µm (on the sensor)")
    medium_index: float = bounded(1.0, 1.0, 2.5, "refractive index of the medium around the sample")
    illumination_na: float = bounded(..., 0.01, 1.6, "NA of the illumination disk; at most the objective NA")
    patterns_deg: list[float] = Field(
        ...,
        min_length=2,
        description="per image of the stack, in its order: the direction of the lit half of the illumination "
        "disk (its outward normal in the illumination-frequency plane), degrees; 0 = +x (columns), 90 = +y (rows)",
    )
    z_um: list[float] | None = Field(
        None, description="a z-stack's focal planes, µm (z > 0 farther from the objective); empty: one image a pattern"
    )

    @model_validator(mode="after")
    def _physical(self) -> DpcOptics:
        if self.objective_na >= self.medium_index:
            raise ValueError(f"objective_na {self.objective_na} must be below medium_index {self.medium_index}")
        if self.illumination_na > self.objective_na * (1 + 1e-9):
            raise ValueError(
                f"illumination_na {self.illumination_na} is above objective_na {self.objective_na} (σ > 1: the "
                "outer source points light a dark field); at most the objective NA"
            )
        if any(not math.isfinite(a) for a in self.patterns_deg):
            raise ValueError("patterns_deg must be finite angles in degrees")
        if self.z_um is not None:
            if not self.z_um or any(not math.isfinite(z) for z in self.z_um):
                raise ValueError("z_um must list finite focal planes in µm (or be left out for one image a pattern)")
            if len(set(self.z_um)) != len(self.z_um):
                raise ValueError("z_um lists a focal plane twice; give each plane of the stack once")
        if self.pixel_um > self.wavelength_um / (4 * self.objective_na):
            raise ValueError(
                f"the object-side pixel {self.pixel_um:.3f} µm (camera_pixel_um / magnification) undersamples the "
                f"images (Nyquist {self.wavelength_um / (4 * self.objective_na):.3f} µm at 2 NA / λ): check "
                "camera_pixel_um and magnification"
            )
        return self

    @classmethod
    def from_yaml(cls, path: str | Path) -> DpcOptics:
        """Read an optics file (YAML or JSON).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        DpcOptics

        Raises
        ------
        SsdpcError
            One line naming the key and the fix.
        """
        data: Any = read_mapping(path, "DPC optics file")
        if "objective" in data and "mla" in data:
            raise SsdpcError(f"{path} is a light-field optics file; `ssdpc dpc` reads a DPC optics file (docs/dpc.md)")
        return cls.from_dict(data, source=str(path))

    @property
    def pixel_um(self) -> float:
        """Object-side pixel, µm."""
        return self.camera_pixel_um / self.magnification

    @property
    def cutoff(self) -> float:
        """Objective pupil radius, cycles/µm (NA / λ)."""
        return self.objective_na / self.wavelength_um

    @property
    def source_radius(self) -> float:
        """Illumination disk radius, cycles/µm (illumination NA / λ)."""
        return self.illumination_na / self.wavelength_um

    @property
    def sigma(self) -> float:
        """Coherence ratio illumination NA / objective NA (at most 1)."""
        return self.illumination_na / self.objective_na

    @property
    def focal_planes_um(self) -> list[float]:
        """The stack's focal planes, µm ([0] for one image a pattern)."""
        return [0.0] if self.z_um is None else list(self.z_um)

    @property
    def is_stack(self) -> bool:
        """Whether each pattern is a z-stack (3D) rather than one image (2D)."""
        return self.z_um is not None

    @property
    def depth_of_field_um(self) -> float:
        """Axial resolution of the brightfield images, µm: λ / (n − √(n² − NA²))."""
        n, na = self.medium_index, self.objective_na
        return self.wavelength_um / (n - math.sqrt(n * n - na * na))
