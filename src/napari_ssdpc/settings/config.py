"""A run configuration: the instrument, the reconstruction settings and the outputs in one object.

It is the one object the CLI, napari, the series runner and the Python API hand down to the
solver; each part reads its own section. ``ssdpc reconstruct --config run.yaml`` reads it, and
the napari dock's "Save settings" writes it::

    optics: {...}            # the optics schema (docs/paper-optics.yaml)
    reconstruction: {...}    # ReconstructionSettings, with one section per phase method
    outputs: {save: [...]}   # OutputSettings: quantities written beside RI

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
from napari_ssdpc.settings.outputs import OutputSettings
from napari_ssdpc.settings.reconstruction import ReconstructionSettings, merge_settings

__all__ = ["RunConfig"]


class RunConfig(SettingsModel):
    """The instrument, how to reconstruct and what to write."""

    optics: Optics = Field(default_factory=Optics.paper, description="the instrument")
    reconstruction: ReconstructionSettings = Field(
        default_factory=ReconstructionSettings, description="how to reconstruct"
    )
    outputs: OutputSettings = Field(default_factory=OutputSettings, description="what to write beside RI")

    @classmethod
    def of(cls, optics: Optics, reconstruction: ReconstructionSettings | None = None, **changes) -> RunConfig:
        """A run configuration from optics and reconstruction settings (keys of it changed).

        Parameters
        ----------
        optics : Optics
        reconstruction : ReconstructionSettings, optional
            Default: the defaults.
        **changes
            Reconstruction keys to change (``z_min_um``, ``method``, ``tv={...}``, ...), and
            ``save`` (quantities beside RI).

        Returns
        -------
        RunConfig
        """
        if not isinstance(optics, Optics):
            raise SsdpcError(
                f"RunConfig.of takes an Optics, got {type(optics).__name__}: use Optics.from_yaml(path) or "
                "Optics.paper()"
            )
        if reconstruction is not None and not isinstance(reconstruction, ReconstructionSettings):
            raise SsdpcError(f"reconstruction must be ReconstructionSettings, got {type(reconstruction).__name__}")
        save = changes.pop("save", ())
        save = [save] if isinstance(save, str) else save
        rec = reconstruction or ReconstructionSettings()
        if changes:
            data = merge_settings(rec.to_dict(), changes)
            rec = ReconstructionSettings.from_dict(data, source="reconstruction settings")
        return cls(
            optics=optics,
            reconstruction=rec,
            outputs=OutputSettings.from_dict({"save": list(save) if isinstance(save, (list, tuple, set)) else save}),
        )

    def replace_reconstruction(self, **changes) -> RunConfig:
        """A copy with reconstruction keys changed (sections merged, as in :meth:`of`).

        Parameters
        ----------
        **changes
            Reconstruction keys, and ``save``.

        Returns
        -------
        RunConfig
        """
        changes.setdefault("save", self.outputs.save)
        return RunConfig.of(self.optics, self.reconstruction, **changes)

    @classmethod
    def from_yaml(cls, path: str | Path, default_optics: Optics | None = None) -> RunConfig:
        """Read a run configuration (or an optics file with a ``reconstruction:`` section).

        Parameters
        ----------
        path : str or Path
        default_optics : Optics, optional
            The optics where the file has no ``optics:`` section (the calibration's); default the
            paper's.

        Returns
        -------
        RunConfig
        """
        data = read_mapping(path, "settings file")
        if "optics" not in data and "wavelength_um" in data:  # an optics file
            data = dict(data)
            rec = data.pop("reconstruction", None) or {}
            data = {"optics": data, "reconstruction": rec}
        if not {"optics", "reconstruction", "outputs"} & set(data):
            raise SsdpcError(
                f"{path}: expected 'optics:', 'reconstruction:' or 'outputs:' sections (a run configuration)"
            )
        if data.get("optics"):
            optics = Optics.from_dict(data["optics"], source=f"{path} optics")
        else:
            optics = default_optics or Optics.paper()
        rec = ReconstructionSettings.from_dict(data.get("reconstruction") or {}, source=f"{path} reconstruction")
        outputs = OutputSettings.from_dict(data.get("outputs") or {}, source=f"{path} outputs")
        extra = sorted(set(data) - {"optics", "reconstruction", "outputs"})
        if extra:
            raise SsdpcError(f"{path}: unknown section '{extra[0]}' (valid: optics, reconstruction, outputs)")
        return cls(optics=optics, reconstruction=rec, outputs=outputs)

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
        data = {
            "optics": self.optics.to_dict(),
            "reconstruction": self.reconstruction.to_dict(),
            "outputs": self.outputs.to_dict(),
        }
        with atomic_write(path) as tmp:
            Path(tmp).write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        return path
