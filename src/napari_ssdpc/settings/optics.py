"""The instrument: objective, Fourier lens, microlens array (MLA), sensor and condenser.

One pydantic model per physical part, nested as in the optics YAML file (see
``docs/paper-optics.yaml``): every length carries its unit in the key (``_um``, ``_mm``,
``_px``). Object-space lengths are micrometres, spatial frequencies cycles per micrometre, and
the wavelength is the vacuum wavelength. The value ranges live once, in the field definitions;
a value outside its range almost always means a wrong unit.

Geometry (docs/conventions.md): the lenslet at MLA position ``a`` (µm, measured from the optical
axis) sees the pupil sub-aperture centred at ``u_k = -a / (λ f_obj m_r)``: the tube-lens /
Fourier-lens relay inverts the back focal plane onto the MLA.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import yaml
from pydantic import Field, model_validator

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.settings.aberrations import Aberrations
from napari_ssdpc.settings.base import SettingsModel, bounded
from napari_ssdpc.settings.files import read_mapping
from napari_ssdpc.settings.parts import MLA, PART_KEYS, Objective, Sensor

__all__ = ["PAPER_OPTICS", "Optics"]


class Optics(SettingsModel):
    """The instrument (the schema of the optics YAML file).

    Attributes of the parts are also readable flat (``optics.na``, ``optics.pitch_um``,
    ``optics.mla_focal_length_mm``, ``optics.pixel_um``...), and :meth:`replace` takes those
    flat names.
    """

    name: str = Field("", description="a name for the instrument")
    wavelength_um: float = bounded(..., 0.2, 2.0, "vacuum wavelength, µm (520 nm is 0.52)")
    medium_index: float = bounded(..., 1.0, 2.5, "refractive index of the immersion/mounting medium")
    condenser_na: float = bounded(..., 0.0, 1.6, "illumination (condenser) NA; below the objective NA")
    objective: Objective
    fourier_lens_mm: float = bounded(..., 5.0, 2000.0, "Fourier-lens focal length, mm")
    mla: MLA
    sensor: Sensor
    iris_radius_um: float | None = bounded(
        None, 1.0, 100000.0, "field-stop radius at the native image plane, µm; empty: EIs just touch (Eq. 9)"
    )
    flip_x: bool = Field(False, description="the camera mirrors x (columns)")
    flip_y: bool = Field(False, description="the camera mirrors y (rows)")
    aberrations: Aberrations = Field(
        default_factory=Aberrations, description="what the instrument adds to the nominal optics (all zero: none)"
    )

    @model_validator(mode="after")
    def _physical(self) -> Optics:
        if self.objective.na >= self.medium_index:
            raise ValueError(
                f"objective.na {self.objective.na} must be below medium_index {self.medium_index}; check both"
            )
        self.check_condenser()
        return self

    # ------------------------------------------------------------------ loading
    @classmethod
    def from_dict(cls, data: Any, source: str = "optics") -> Optics:
        """Validate an optics mapping (a ``reconstruction:`` section in it is checked and set aside).

        Parameters
        ----------
        data : dict
            Keys as in the optics YAML file.
        source : str
            Where it came from, for the messages.

        Returns
        -------
        Optics
        """
        if isinstance(data, dict) and "reconstruction" in data:
            from napari_ssdpc.settings.reconstruction import ReconstructionSettings

            data = dict(data)
            ReconstructionSettings.from_dict(data.pop("reconstruction") or {}, source=f"{source} reconstruction")
        return super().from_dict(data, source)

    @classmethod
    def from_yaml(cls, path: str | Path) -> Optics:
        """Read an optics YAML file, or the ``optics:`` section of a run configuration.

        Parameters
        ----------
        path : str or Path
            The YAML file (lengths carry their unit in the key, e.g. ``pitch_um``).

        Returns
        -------
        Optics

        Raises
        ------
        SsdpcError
            One line naming the key, the value and the fix.
        """
        data = read_mapping(path, "optics file")
        if "optics" in data and isinstance(data["optics"], dict):
            data = data["optics"]
        return cls.from_dict(data, source=str(path))

    @classmethod
    def paper(cls) -> Optics:
        """The paper's instrument (section 3.1), our default optics."""
        return cls.from_dict(PAPER_OPTICS, source="paper optics")

    def to_dict(self) -> dict:
        """The YAML schema as a plain mapping (``iris_radius_um`` and ``aberrations`` only when set)."""
        d = super().to_dict()
        if d["iris_radius_um"] is None:
            del d["iris_radius_um"]
        if self.aberrations.is_nominal:
            del d["aberrations"]
        return d

    def to_yaml(self, path: str | Path) -> Path:
        """Write the optics YAML file (atomically: a failed write leaves the old file).

        Parameters
        ----------
        path : str or Path
            The YAML file; :meth:`from_yaml` reads it back.

        Returns
        -------
        Path
        """
        from napari_ssdpc.files import atomic_write

        path = Path(path)
        with atomic_write(path) as tmp:
            tmp.write_text(yaml.safe_dump(self.to_dict(), sort_keys=False), encoding="utf-8")
        return path

    def replace(self, **changes: Any) -> Optics:
        """A validated copy with some fields changed; parts' fields may be named flat (``na=0.3``)."""
        d = self.to_dict()
        for key, value in changes.items():
            if key in PART_KEYS:
                part, sub = PART_KEYS[key]
                d[part] = {**d[part], sub: value}
            else:
                d[key] = value
        return type(self).from_dict(d, source="optics")

    def check_condenser(self) -> None:
        """sigma >= 1 is an error (no phase contrast with a split detection pupil), > 0.8 a warning."""
        na = self.objective.na
        if self.condenser_na >= na:
            raise SsdpcError(
                f"condenser_na {self.condenser_na} >= objective NA {na}: no phase contrast with a split "
                "detection pupil (docs/conventions.md); close the condenser aperture (e.g. condenser_na 0.3 x NA)"
            )
        if self.condenser_na > 0.8 * na:
            warnings.warn(
                f"condenser_na {self.condenser_na} is above 0.8 x objective NA (coherence ratio {self.sigma:.2f}): "
                "phase contrast is weak; close the condenser aperture for a better phase signal",
                SsdpcWarning,
                stacklevel=3,
            )

    # ----------------------------------------------------- flat part attributes
    @property
    def magnification(self) -> float:
        """objective.magnification (x)"""
        return self.objective.magnification

    @property
    def na(self) -> float:
        """objective.na"""
        return self.objective.na

    @property
    def tube_lens_mm(self) -> float:
        """objective.tube_lens_mm (mm)"""
        return self.objective.tube_lens_mm

    @property
    def pitch_um(self) -> float:
        """mla.pitch_um (µm)"""
        return self.mla.pitch_um

    @property
    def mla_focal_length_mm(self) -> float:
        """mla.focal_length_mm (mm)"""
        return self.mla.focal_length_mm

    @property
    def lenslet_radius_um(self) -> float:
        """mla.lenslet_radius_um (µm)"""
        return self.mla.lenslet_radius_um

    @property
    def grid(self) -> str:
        """mla.grid ('square' or 'hex')"""
        return self.mla.grid

    @property
    def pixel_um(self) -> float:
        """sensor.pixel_um (µm)"""
        return self.sensor.pixel_um

    @property
    def width_px(self) -> int:
        """sensor.width_px"""
        return self.sensor.width_px

    @property
    def height_px(self) -> int:
        """sensor.height_px"""
        return self.sensor.height_px

    # ------------------------------------------------------- derived quantities
    @property
    def f_obj_um(self) -> float:
        """Objective focal length f_tube / M, µm."""
        return self.tube_lens_mm * 1000.0 / self.magnification

    @property
    def m_r(self) -> float:
        """BFP-to-MLA magnification f_fl / f_tube (the paper's M_relay)."""
        return self.fourier_lens_mm / self.tube_lens_mm

    @property
    def m_ei(self) -> float:
        """Object-to-sensor magnification of an elemental image, M f_ml / f_fl."""
        return self.magnification * self.mla_focal_length_mm / self.fourier_lens_mm

    @property
    def object_pixel_um(self) -> float:
        """Sensor pixel in object space, pixel / M_EI, µm."""
        return self.pixel_um / self.m_ei

    @property
    def pitch_px(self) -> float:
        """Lenslet pitch on the sensor, px."""
        return self.pitch_um / self.pixel_um

    @property
    def iris_radius_nip_um(self) -> float:
        """Iris radius at the native image plane; default makes EIs tangent (Eq. 9)."""
        if self.iris_radius_um is not None:
            return self.iris_radius_um
        return self.lenslet_radius_um * self.fourier_lens_mm / self.mla_focal_length_mm

    @property
    def ei_radius_um(self) -> float:
        """EI radius on the sensor, R_EI = r_iris f_ml / f_fl (Eq. 8)."""
        return self.iris_radius_nip_um * self.mla_focal_length_mm / self.fourier_lens_mm

    @property
    def ei_radius_px(self) -> float:
        """EI radius on the sensor, px."""
        return self.ei_radius_um / self.pixel_um

    @property
    def fov_um(self) -> float:
        """Field of view D_FOV = 2 r_iris f_obj / f_tube (Eq. 10)."""
        return 2.0 * self.iris_radius_nip_um * self.f_obj_um / (self.tube_lens_mm * 1000.0)

    @property
    def field_radius_um(self) -> float:
        """Radius of the field of view in object space, µm."""
        return 0.5 * self.fov_um

    @property
    def subaperture_na(self) -> float:
        """NA of one lenslet's pupil sub-aperture, r_ml / (f_obj m_r)."""
        return self.lenslet_radius_um / (self.f_obj_um * self.m_r)

    @property
    def sigma(self) -> float:
        """Coherence ratio condenser NA / objective NA."""
        return self.condenser_na / self.na

    @property
    def pupil_radius_mla_um(self) -> float:
        """Radius of the objective pupil imaged onto the MLA, f_obj NA m_r."""
        return self.f_obj_um * self.na * self.m_r

    @property
    def cutoff(self) -> float:
        """Objective pupil radius in cycles/µm, NA / λ."""
        return self.na / self.wavelength_um

    @property
    def subaperture_radius(self) -> float:
        """Sub-aperture radius in cycles/µm, r_ml / (λ f_obj m_r)."""
        return self.subaperture_na / self.wavelength_um

    @property
    def source_centre(self) -> tuple[float, float]:
        """The condenser disk's centre (x, y), cycles/µm: (0, 0) unless the aberrations put it off axis."""
        cx, cy = self.aberrations.condenser_offset_na
        return cx / self.wavelength_um, cy / self.wavelength_um

    @property
    def source_radius(self) -> float:
        """Condenser disk radius in cycles/µm."""
        return self.condenser_na / self.wavelength_um


PAPER_OPTICS = {
    "wavelength_um": 0.52,
    "medium_index": 1.518,
    "condenser_na": 0.1,
    "objective": {"magnification": 20, "na": 0.4, "tube_lens_mm": 200},
    "fourier_lens_mm": 75,
    "mla": {"pitch_um": 500, "focal_length_mm": 15.3, "lenslet_radius_um": 250, "grid": "square"},
    "sensor": {"pixel_um": 3.45, "width_px": 2448, "height_px": 2048},
    "name": "paper (qRPM, 20x/0.4, f_fl 75 mm, MLA 500 µm / 15.3 mm)",
}
