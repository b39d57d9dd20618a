"""Optics of a Fourier light-field microscope and the paper's design calculator.

The schema is the one of ``shared/paper-optics.yaml``: every length carries its unit
in the key (``_um``, ``_mm``, ``_px``). Object-space lengths are micrometres, spatial
frequencies are cycles per micrometre, and the wavelength is the vacuum wavelength.

Conventions (DESIGN.md §3): the lenslet at MLA position ``a`` (µm, measured from the
optical axis) sees the pupil sub-aperture centred at ``u_k = -a / (λ f_obj m_r)``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from napari_ssdpc.errors import SsdpcError, SsdpcWarning

#: Reconstruction settings that a ``reconstruction:`` section may hold, with defaults.
RECONSTRUCTION_DEFAULTS = {
    "z_min_um": -80.0,
    "z_max_um": 80.0,
    "dz_um": 1.0,
    "rl_iterations": 15,
    "tikhonov_alpha": None,  # None: the method's default (DEFAULT_ALPHA)
    "model": "lenslet",
    "method": "wotf",
}
TRANSFER_MODELS = ("lenslet", "paper")
#: 'wotf': 3D Tikhonov over all views with their defocused WOTFs; 'rl': the paper's route
#: (Richardson-Lucy per half, DPC per slice, 2D Tikhonov with the in-focus DPC transfer function).
PHASE_METHODS = ("wotf", "rl")
#: Tikhonov alpha per method: 'rl' on the |H_DPC|² scale of Eq. 7, 'wotf' relative to the strongest
#: view's |H|² summed over z (docs/validation.md).
DEFAULT_ALPHA = {"wotf": 0.1, "rl": 0.01}

# Sanity ranges: a value outside them almost always means a wrong unit.
_RANGES = {
    "wavelength_um": (0.2, 2.0, "µm (520 nm is 0.52)"),
    "medium_index": (1.0, 2.5, ""),
    "condenser_na": (0.0, 1.6, ""),
    "objective.magnification": (1.0, 200.0, "x"),
    "objective.na": (0.01, 1.7, ""),
    "objective.tube_lens_mm": (20.0, 1000.0, "mm (a tube lens is 160-200 mm)"),
    "fourier_lens_mm": (5.0, 2000.0, "mm"),
    "mla.pitch_um": (10.0, 10000.0, "µm (500 µm is 0.5 mm)"),
    "mla.focal_length_mm": (0.1, 500.0, "mm"),
    "mla.lenslet_radius_um": (5.0, 10000.0, "µm"),
    "sensor.pixel_um": (0.5, 50.0, "µm"),
    "sensor.width_px": (16, 100000, "px"),
    "sensor.height_px": (16, 100000, "px"),
}
_SCHEMA = {
    "wavelength_um": None,
    "medium_index": None,
    "condenser_na": None,
    "objective": ("magnification", "na", "tube_lens_mm"),
    "fourier_lens_mm": None,
    "mla": ("pitch_um", "focal_length_mm", "lenslet_radius_um", "grid"),
    "sensor": ("pixel_um", "width_px", "height_px"),
}
_OPTIONAL = {"flip_x", "flip_y", "iris_radius_um", "reconstruction", "name"}
GRIDS = ("square",)


@dataclass(frozen=True)
class Lenslet:
    """One lenslet that overlaps the objective pupil.

    ``row``/``col`` index the lattice: the lenslet centre sits at
    ``((col + 0.5) p, (row + 0.5) p)`` from the reference lattice vertex, so the four
    central lenslets are (-1,-1), (-1,0), (0,-1) and (0,0). ``a_um`` is the centre
    measured from the optical axis in the MLA plane (x right, y down), ``u`` the
    sub-aperture centre frequency (cycles/µm), ``fraction`` the part of the lenslet
    aperture inside the objective pupil.
    """

    row: int
    col: int
    a_um: tuple[float, float]
    u: tuple[float, float]
    fraction: float

    @property
    def halves(self) -> tuple[str, ...]:
        """Halves of paper Eq. 5 this lenslet belongs to (DESIGN.md §3)."""
        ax, ay = self.a_um
        out = []
        if ay < 0:
            out.append("up")
        elif ay > 0:
            out.append("down")
        if ax < 0:
            out.append("left")
        elif ax > 0:
            out.append("right")
        return tuple(out)


def circle_overlap_fraction(d, r_small, r_big):
    """Fraction of a circle of radius ``r_small`` inside a circle of radius ``r_big``
    whose centres are ``d`` apart (exact lens-area formula, vectorised)."""
    d = np.abs(np.asarray(d, dtype=float))
    r, R = float(r_small), float(r_big)
    out = np.zeros_like(d)
    inside = d <= abs(R - r)
    out[inside] = 1.0 if r <= R else (R / r) ** 2
    part = (~inside) & (d < R + r)
    dp = d[part]
    a1 = r * r * np.arccos(np.clip((dp * dp + r * r - R * R) / (2 * dp * r), -1, 1))
    a2 = R * R * np.arccos(np.clip((dp * dp + R * R - r * r) / (2 * dp * R), -1, 1))
    a3 = 0.5 * np.sqrt(np.clip((-dp + r + R) * (dp + r - R) * (dp - r + R) * (dp + r + R), 0, None))
    out[part] = (a1 + a2 - a3) / (math.pi * r * r)
    return out


@dataclass(frozen=True)
class Optics:
    """Instrument description (schema of ``shared/paper-optics.yaml``)."""

    wavelength_um: float
    medium_index: float
    condenser_na: float
    magnification: float
    na: float
    tube_lens_mm: float
    fourier_lens_mm: float
    pitch_um: float
    mla_focal_length_mm: float
    lenslet_radius_um: float
    pixel_um: float
    width_px: int
    height_px: int
    grid: str = "square"
    iris_radius_um: float | None = None  # at the native image plane; None = EIs tangent (Eq. 9)
    flip_x: bool = False
    flip_y: bool = False
    reconstruction: dict = field(default_factory=lambda: dict(RECONSTRUCTION_DEFAULTS))
    name: str = ""

    def __post_init__(self):
        self.validate()

    # ------------------------------------------------------------------ loading
    @classmethod
    def from_dict(cls, d: dict, source: str = "optics") -> Optics:
        """Build from a dict in the YAML schema; one-line errors for bad content."""
        if not isinstance(d, dict):
            raise SsdpcError(f"{source}: expected a mapping of optics keys, got {type(d).__name__}")
        for key, sub in _SCHEMA.items():
            if key not in d:
                raise SsdpcError(f"{source}: missing key '{key}' (see shared/paper-optics.yaml)")
            if sub is not None:
                if not isinstance(d[key], dict):
                    raise SsdpcError(f"{source}: '{key}' must be a mapping with keys {', '.join(sub)}")
                for s in sub:
                    if s not in d[key]:
                        hint = _unit_hint(s, d[key])
                        raise SsdpcError(f"{source}: missing key '{key}.{s}'{hint}")
                for s in d[key]:
                    if s not in sub:
                        raise SsdpcError(f"{source}: unknown key '{key}.{s}'{_unit_hint(s, sub, unknown=True)}")
        for key in d:
            if key not in _SCHEMA and key not in _OPTIONAL:
                raise SsdpcError(
                    f"{source}: unknown key '{key}'{_unit_hint(key, list(_SCHEMA) + list(_OPTIONAL), unknown=True)}"
                )
        rec = dict(RECONSTRUCTION_DEFAULTS)
        extra = d.get("reconstruction") or {}
        if not isinstance(extra, dict):
            raise SsdpcError(f"{source}: 'reconstruction' must be a mapping")
        for k in extra:
            if k not in RECONSTRUCTION_DEFAULTS:
                raise SsdpcError(
                    f"{source}: unknown key 'reconstruction.{k}' (allowed: {', '.join(RECONSTRUCTION_DEFAULTS)})"
                )
        rec.update(extra)
        o, m, s = d["objective"], d["mla"], d["sensor"]
        try:
            return cls(
                wavelength_um=_num(d, "wavelength_um", source),
                medium_index=_num(d, "medium_index", source),
                condenser_na=_num(d, "condenser_na", source, allow_zero=True),
                magnification=_num(o, "magnification", source, "objective."),
                na=_num(o, "na", source, "objective."),
                tube_lens_mm=_num(o, "tube_lens_mm", source, "objective."),
                fourier_lens_mm=_num(d, "fourier_lens_mm", source),
                pitch_um=_num(m, "pitch_um", source, "mla."),
                mla_focal_length_mm=_num(m, "focal_length_mm", source, "mla."),
                lenslet_radius_um=_num(m, "lenslet_radius_um", source, "mla."),
                grid=str(m["grid"]),
                pixel_um=_num(s, "pixel_um", source, "sensor."),
                width_px=int(_num(s, "width_px", source, "sensor.")),
                height_px=int(_num(s, "height_px", source, "sensor.")),
                iris_radius_um=None if d.get("iris_radius_um") is None else _num(d, "iris_radius_um", source),
                flip_x=bool(d.get("flip_x", False)),
                flip_y=bool(d.get("flip_y", False)),
                reconstruction=rec,
                name=str(d.get("name", "")),
            )
        except SsdpcError as e:
            msg = str(e)
            raise SsdpcError(msg if msg.startswith(source) else f"{source}: {msg}") from None

    @classmethod
    def from_yaml(cls, path) -> Optics:
        path = Path(path)
        if not path.is_file():
            raise SsdpcError(f"optics file not found: {path} (give the path to a YAML like shared/paper-optics.yaml)")
        try:
            d = yaml.safe_load(path.read_text())
        except yaml.YAMLError as e:
            line = getattr(getattr(e, "problem_mark", None), "line", None)
            where = f" at line {line + 1}" if line is not None else ""
            raise SsdpcError(f"{path}: not valid YAML{where}; fix the syntax") from None
        return cls.from_dict(d, source=str(path))

    @classmethod
    def paper(cls) -> Optics:
        """The paper's instrument (section 3.1), our default optics."""
        return cls.from_dict(PAPER_OPTICS, source="paper optics")

    def to_dict(self) -> dict:
        d = {
            "wavelength_um": self.wavelength_um,
            "medium_index": self.medium_index,
            "condenser_na": self.condenser_na,
            "objective": {"magnification": self.magnification, "na": self.na, "tube_lens_mm": self.tube_lens_mm},
            "fourier_lens_mm": self.fourier_lens_mm,
            "mla": {
                "pitch_um": self.pitch_um,
                "focal_length_mm": self.mla_focal_length_mm,
                "lenslet_radius_um": self.lenslet_radius_um,
                "grid": self.grid,
            },
            "sensor": {"pixel_um": self.pixel_um, "width_px": self.width_px, "height_px": self.height_px},
            "flip_x": self.flip_x,
            "flip_y": self.flip_y,
            "reconstruction": dict(self.reconstruction),
        }
        if self.iris_radius_um is not None:
            d["iris_radius_um"] = self.iris_radius_um
        if self.name:
            d["name"] = self.name
        return d

    def to_yaml(self, path) -> None:
        Path(path).write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))

    def replace(self, **changes) -> Optics:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    # --------------------------------------------------------------- validation
    def validate(self) -> None:
        flat = asdict(self)
        names = {
            "objective.magnification": "magnification",
            "objective.na": "na",
            "objective.tube_lens_mm": "tube_lens_mm",
            "mla.pitch_um": "pitch_um",
            "mla.focal_length_mm": "mla_focal_length_mm",
            "mla.lenslet_radius_um": "lenslet_radius_um",
            "sensor.pixel_um": "pixel_um",
            "sensor.width_px": "width_px",
            "sensor.height_px": "height_px",
        }
        for key, (lo, hi, unit) in _RANGES.items():
            v = flat[names.get(key, key)]
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise SsdpcError(f"'{key}' must be a finite number, got {v!r}")
            if key != "condenser_na" and v <= 0:
                raise SsdpcError(f"'{key}' must be positive, got {v}")
            if not lo <= v <= hi:
                raise SsdpcError(f"'{key}' = {v} is outside {lo}-{hi}; check the unit{': ' + unit if unit else ''}")
        if self.grid not in GRIDS:
            raise SsdpcError(f"unknown MLA grid '{self.grid}'; supported: {', '.join(GRIDS)}")
        if self.na >= self.medium_index:
            raise SsdpcError(f"objective NA {self.na} must be below the medium index {self.medium_index}")
        if self.condenser_na < 0:
            raise SsdpcError(f"condenser_na must be >= 0, got {self.condenser_na}")
        if self.lenslet_radius_um > 0.5 * self.pitch_um * 1.0001:
            raise SsdpcError(
                f"lenslet radius {self.lenslet_radius_um} µm exceeds half the pitch {self.pitch_um} µm; check mla.lenslet_radius_um"  # noqa: E501
            )
        if self.iris_radius_um is not None and self.iris_radius_um <= 0:
            raise SsdpcError(f"'iris_radius_um' must be positive, got {self.iris_radius_um}")
        rec = self.reconstruction
        if rec.get("model") not in TRANSFER_MODELS:
            raise SsdpcError(
                f"reconstruction.model must be one of {', '.join(TRANSFER_MODELS)}, got {rec.get('model')!r}"
            )
        if rec.get("method") not in PHASE_METHODS:
            raise SsdpcError(
                f"reconstruction.method must be one of {', '.join(PHASE_METHODS)}, got {rec.get('method')!r}"
            )
        if not float(rec["dz_um"]) > 0:
            raise SsdpcError(f"reconstruction.dz_um must be > 0, got {rec['dz_um']}")
        if not float(rec["z_max_um"]) >= float(rec["z_min_um"]):
            raise SsdpcError("reconstruction.z_max_um must be >= z_min_um")
        if int(rec["rl_iterations"]) < 1:
            raise SsdpcError(f"reconstruction.rl_iterations must be >= 1, got {rec['rl_iterations']}")
        if rec["tikhonov_alpha"] is not None and not float(rec["tikhonov_alpha"]) > 0:
            raise SsdpcError(f"reconstruction.tikhonov_alpha must be > 0, got {rec['tikhonov_alpha']}")
        self.check_condenser()

    def check_condenser(self) -> None:
        """σ >= 1 is an error, σ > 0.8 a warning (DESIGN.md §4.2)."""
        if self.condenser_na >= self.na:
            raise SsdpcError(
                f"condenser_na {self.condenser_na} >= objective NA {self.na}: no phase contrast with a split "
                "detection pupil, see DESIGN.md §4.2; close the condenser aperture (e.g. condenser_na 0.1-0.3)"
            )
        if self.condenser_na > 0.8 * self.na:
            warnings.warn(
                f"condenser_na {self.condenser_na} is above 0.8 x objective NA ({self.sigma:.2f} coherence ratio): "
                "phase contrast is weak; close the condenser aperture for a better phase signal",
                SsdpcWarning,
                stacklevel=3,
            )

    # ------------------------------------------------------- derived quantities
    @property
    def f_obj_um(self) -> float:
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
        return self.pixel_um / self.m_ei

    @property
    def pitch_px(self) -> float:
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
        return self.ei_radius_um / self.pixel_um

    @property
    def fov_um(self) -> float:
        """Field of view D_FOV = 2 r_iris f_obj / f_tube (Eq. 10)."""
        return 2.0 * self.iris_radius_nip_um * self.f_obj_um / (self.tube_lens_mm * 1000.0)

    @property
    def field_radius_um(self) -> float:
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
    def source_radius(self) -> float:
        """Condenser disk radius in cycles/µm."""
        return self.condenser_na / self.wavelength_um

    def mla_to_frequency(self, a_um):
        """u_k = -a / (λ f_obj m_r) in cycles/µm (DESIGN.md §3: the relay inverts the BFP)."""
        return -np.asarray(a_um, dtype=float) / (self.wavelength_um * self.f_obj_um * self.m_r)

    def lenslets(self, axis_offset_um=(0.0, 0.0), min_fraction: float = 1e-3) -> list[Lenslet]:
        """Lenslets overlapping the objective pupil.

        ``axis_offset_um`` is the optical axis position relative to the reference
        lattice vertex in the MLA plane (x, y), so a lenslet centre relative to the
        axis is its lattice position minus that offset.
        """
        p = self.pitch_um
        ox, oy = (float(v) for v in axis_offset_um)
        n = int(math.ceil((self.pupil_radius_mla_um + self.lenslet_radius_um) / p)) + 1
        idx = np.arange(-n - 1, n + 1)
        out = []
        for row in idx:
            for col in idx:
                ax, ay = (col + 0.5) * p - ox, (row + 0.5) * p - oy
                frac = float(
                    circle_overlap_fraction(math.hypot(ax, ay), self.lenslet_radius_um, self.pupil_radius_mla_um)
                )
                if frac >= min_fraction:
                    u = self.mla_to_frequency((ax, ay))
                    out.append(Lenslet(int(row), int(col), (ax, ay), (float(u[0]), float(u[1])), frac))
        return out

    def tan_theta(self, u) -> np.ndarray:
        """tan of the propagation angle in the medium for frequency |u| (cycles/µm)."""
        s = np.clip(self.wavelength_um * np.linalg.norm(np.atleast_2d(u), axis=-1) / self.medium_index, 0, 0.999999)
        return s / np.sqrt(1 - s * s)

    # ------------------------------------------------------ design calculator
    def design(self) -> dict:
        """Paper Eqs. 8-14 and the DOF limits of section 3.2 (lengths in µm)."""
        lam, M, NA = self.wavelength_um, self.magnification, self.na
        f_fl, f_ml = self.fourier_lens_mm * 1e3, self.mla_focal_length_mm * 1e3
        f_tube, f_obj, d = self.tube_lens_mm * 1e3, self.f_obj_um, self.pitch_um
        na_ml = self.lenslet_radius_um / f_ml
        r_nip = lam / (2 * na_ml)  # Eq. 11
        r_xy = r_nip * (f_fl / f_ml) / M  # Eq. 12
        tan_printed = math.sqrt(2) * d / f_ml  # Eq. 13 as printed
        tan_ffl = math.sqrt(2) * d / f_fl  # reproduces the printed 20.6 µm
        rz_printed = r_nip * (f_fl / f_ml) / tan_printed / M**2
        rz_ffl = r_nip * (f_fl / f_ml) / tan_ffl / M**2
        m_t = (2 * f_fl * NA / f_tube) * (f_obj / d)
        dof_fwhm = m_t**2 * lam / NA**2 + self.pixel_um * m_t**2 / (M * NA)  # Eq. 14
        dof_pitch = d * (f_fl / f_ml) / (d / f_fl) / M**2
        lens = self.lenslets()
        usable = [ln for ln in lens if ln.fraction >= 0.5]
        tan_edge = float(np.max(self.tan_theta(np.array([ln.u for ln in lens]))))
        regimes = [self.illumination_regime(ln) for ln in lens]
        return {
            "ei_radius_um": self.ei_radius_um,  # Eq. 8
            "iris_radius_um": self.iris_radius_nip_um,  # Eq. 9
            "fov_um": self.fov_um,  # Eq. 10
            "r_nip_um": r_nip,  # Eq. 11
            "r_xy_um": r_xy,  # Eq. 12
            "r_z_printed_um": rz_printed,
            "r_z_ffl_um": rz_ffl,
            "m_t": m_t,
            "dof_fwhm_um": dof_fwhm,
            "dof_full_um": 2 * dof_fwhm,
            "dof_pitch_um": dof_pitch,
            "dof_um": min(2 * dof_fwhm, dof_pitch),
            "m_ei": self.m_ei,
            "object_pixel_um": self.object_pixel_um,
            "f_obj_um": f_obj,
            "m_r": self.m_r,
            "subaperture_na": self.subaperture_na,
            "sigma": self.sigma,
            "pitch_px": self.pitch_px,
            "ei_radius_px": self.ei_radius_px,
            "lenslets_in_pupil": len(lens),
            "lenslets_usable": len(usable),
            "nyquist_voxel_xy_um": r_xy / 2,
            "nyquist_voxel_z_um": rz_ffl / 2,
            "max_tan_theta": tan_edge,
            "lenslets_brightfield": regimes.count("brightfield"),
            "lenslets_straddling": regimes.count("straddling"),
            "lenslets_darkfield": regimes.count("darkfield"),
        }

    def illumination_regime(self, lenslet: Lenslet) -> str:
        """Where a lenslet's sub-aperture lies relative to the source disk (DESIGN.md §4.2):
        'brightfield' (wholly inside: defocus contrast only), 'straddling' (DPC-like
        contrast) or 'darkfield' (wholly outside: second order in the weak-object model)."""
        na_k = self.wavelength_um * math.hypot(*lenslet.u)
        if na_k + self.subaperture_na <= self.condenser_na:
            return "brightfield"
        if na_k - self.subaperture_na >= self.condenser_na:
            return "darkfield"
        return "straddling"


def design_table(optics: Optics) -> str:
    """Readable design summary for ``ssdpc design``."""
    d = optics.design()
    rows = [
        ("Elemental-image magnification M_EI", f"{d['m_ei']:.4g}", "x"),
        ("Object pixel size", f"{d['object_pixel_um']:.4f}", "µm"),
        ("Lenslet pitch on sensor", f"{d['pitch_px']:.2f}", "px"),
        ("EI radius R_EI (Eq. 8)", f"{d['ei_radius_um']:.1f} µm = {d['ei_radius_px']:.2f}", "px"),
        ("Iris radius at NIP (Eq. 9)", f"{d['iris_radius_um']:.1f}", "µm"),
        ("Field of view D_FOV (Eq. 10)", f"{d['fov_um']:.2f}", "µm"),
        ("Sub-aperture NA (object side)", f"{d['subaperture_na']:.4f}", ""),
        ("Coherence ratio sigma = NA_c / NA", f"{d['sigma']:.3f}", ""),
        ("Lateral resolution R_xy (Eq. 12)", f"{d['r_xy_um']:.2f}", "µm"),
        ("Axial resolution R_z, Eq. 13 as printed (tan = sqrt2 d/f_ml)", f"{d['r_z_printed_um']:.2f}", "µm"),
        (
            "Axial resolution R_z with tan = sqrt2 d/f_fl (matches paper's 20.6, measured 21.96)",
            f"{d['r_z_ffl_um']:.2f}",
            "µm",
        ),
        ("DOF, FWHM of central-lenslet PSF (Eq. 14)", f"{d['dof_fwhm_um']:.2f}", "µm"),
        ("DOF, full width (2 x FWHM)", f"{d['dof_full_um']:.2f}", "µm"),
        ("DOF, pitch-limited", f"{d['dof_pitch_um']:.1f}", "µm"),
        ("DOF, usable (smaller of the two)", f"{d['dof_um']:.2f}", "µm"),
        ("Lenslets overlapping the pupil", f"{d['lenslets_in_pupil']}", ""),
        ("Usable lenslets (>= 50% inside the pupil)", f"{d['lenslets_usable']}", ""),
        (
            "Lenslets inside / straddling / outside the source disk",
            f"{d['lenslets_brightfield']} / {d['lenslets_straddling']} / {d['lenslets_darkfield']}",
            "",
        ),
        ("Nyquist voxel, lateral (R_xy / 2)", f"{d['nyquist_voxel_xy_um']:.2f}", "µm"),
        ("Nyquist voxel, axial (R_z / 2)", f"{d['nyquist_voxel_z_um']:.2f}", "µm"),
    ]
    w = max(len(r[0]) for r in rows)
    lines = [f"{n:<{w}}  {v} {u}".rstrip() for n, v, u in rows]
    lines.append("Note: the paper's measured axial resolution (21.96 µm) matches the f_fl variant of R_z.")
    return "\n".join(lines)


def _num(d, key, source, prefix="", allow_zero=False):
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        if isinstance(v, str):
            try:
                return float(v)
            except ValueError:
                pass
        raise SsdpcError(f"{source}: '{prefix}{key}' must be a number, got {v!r} (the unit is in the key name)")
    v = float(v)
    if not math.isfinite(v):
        raise SsdpcError(f"{source}: '{prefix}{key}' must be finite, got {v}")
    if v < 0 or (v == 0 and not allow_zero):
        raise SsdpcError(f"{source}: '{prefix}{key}' must be positive, got {v}")
    return v


def _unit_hint(key, candidates, unknown=False):
    """Point at a key that differs only in its unit suffix (e.g. pitch_mm vs pitch_um)."""
    stem = key.rsplit("_", 1)[0]
    for c in candidates:
        if c != key and c.rsplit("_", 1)[0] == stem:
            if unknown:
                return f" (expected '{c}': lengths carry their unit in the key)"
            return f" (found '{c}' instead: convert the value and rename the key to '{key}')"
    return " (not part of the optics schema)" if unknown else ""


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
