"""A run configuration: the instrument and the reconstruction settings in one YAML file.

``ssdpc reconstruct --config run.yaml`` reads it, and the napari dock's "Save settings" writes
it::

    optics: {...}            # the optics schema (docs/paper-optics.yaml)
    reconstruction: {...}    # ReconstructionSettings

An optics file with a ``reconstruction:`` section reads as a run configuration too.
"""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import Field

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.base import SettingsModel
from napari_ssdpc.settings.files import read_mapping
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import ReconstructionSettings

__all__ = ["RunConfig"]


class RunConfig(SettingsModel):
    """The instrument and how to reconstruct."""

    optics: Optics = Field(default_factory=Optics.paper, description="the instrument")
    reconstruction: ReconstructionSettings = Field(
        default_factory=ReconstructionSettings, description="how to reconstruct"
    )

    @classmethod
    def from_yaml(cls, path: str | Path) -> RunConfig:
        """Read a run configuration (or an optics file with a ``reconstruction:`` section).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        RunConfig
        """
        data = read_mapping(path, "settings file")
        if "optics" not in data and "wavelength_um" in data:  # an optics file
            data = dict(data)
            rec = data.pop("reconstruction", None) or {}
            data = {"optics": data, "reconstruction": rec}
        if "optics" not in data and "reconstruction" not in data:
            raise SsdpcError(f"{path}: expected 'optics:' and 'reconstruction:' sections (a run configuration)")
        optics = Optics.from_dict(data.get("optics") or Optics.paper().to_dict(), source=f"{path} optics")
        rec = ReconstructionSettings.from_dict(data.get("reconstruction") or {}, source=f"{path} reconstruction")
        extra = sorted(set(data) - {"optics", "reconstruction"})
        if extra:
            raise SsdpcError(f"{path}: unknown section '{extra[0]}' (valid: optics, reconstruction)")
        return cls(optics=optics, reconstruction=rec)

    def to_yaml(self, path: str | Path) -> Path:
        """Write the configuration as YAML (atomically).

        Parameters
        ----------
        path : str or Path
            The YAML file; ``ssdpc reconstruct --config`` and the napari dock read it back.

        Returns
        -------
        Path
        """
        from napari_ssdpc.files import atomic_write

        path = Path(path)
        data = {"optics": self.optics.to_dict(), "reconstruction": self.reconstruction.to_dict()}
        with atomic_write(path) as tmp:
            Path(tmp).write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        return path
