"""Reconstruction settings: the z grid, the phase method with its own section, the device.

These are the user's choices for one run, apart from the instrument (:mod:`.optics`) and what
is written (:mod:`.outputs`). Every phase method reads its own section: ``tv``, ``wotf`` or
``rl`` (the methods of :mod:`napari_ssdpc.reconstruction.methods`)::

    reconstruction:
      z_min_um: -40
      z_max_um: 40
      dz_um: 1
      method: tv
      tv: {sign: auto, iterations: 60}
      rl: {iterations: 15}

The CLI builds its options, choices and help defaults from these fields, the napari dock builds
its controls from them, and a run configuration file (:mod:`.config`) stores them. Files written
before the sections existed (``tikhonov_alpha``, ``rl_iterations``, ``tv_lambda``, ... at the top
level) are read into the sections.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Literal, get_args

from pydantic import Field, model_validator

from napari_ssdpc.settings.base import SettingsModel, bounded

__all__ = [
    "DEFAULT_Z_UM",
    "MAX_PLANES",
    "PHASE_METHODS",
    "SIGNS",
    "TRANSFER_MODELS",
    "MethodName",
    "MultisliceSettings",
    "ReconstructionSettings",
    "RlSettings",
    "Sign",
    "TvSettings",
    "WotfSettings",
    "alpha_section",
    "merge_settings",
    "plane_count",
]

#: The phase methods, in the order the CLI and napari list them (their solvers:
#: :data:`napari_ssdpc.reconstruction.methods.METHODS`).
MethodName = Literal["tv", "wotf", "rl", "multislice"]
PHASE_METHODS: tuple[str, ...] = get_args(MethodName)
#: The sign of Δn against the medium: cells in water are denser, PMMA beads in oil lighter.
Sign = Literal["auto", "denser", "lighter", "any"]
SIGNS: tuple[str, ...] = get_args(Sign)
TransferModel = Literal["lenslet", "paper"]
TRANSFER_MODELS: tuple[str, ...] = get_args(TransferModel)
#: The default z range, µm from the focal plane.
DEFAULT_Z_UM = (-80.0, 80.0)
#: More planes than this is almost always a wrong unit or a typo in the z range.
MAX_PLANES = 2001


def plane_count(z_min_um: float, z_max_um: float, dz_um: float) -> int:
    """Planes from z_min to z_max (inclusive) every dz µm: the one rule for the z grid.

    Parameters
    ----------
    z_min_um, z_max_um : float
        First and last plane, µm.
    dz_um : float
        Spacing, µm (> 0).

    Returns
    -------
    int
    """
    return int(math.floor((z_max_um - z_min_um) / dz_um + 1e-6)) + 1


def alpha_section(method: str) -> str:
    """The section that holds a method's Tikhonov α (the multislice method starts from 'tv').

    Parameters
    ----------
    method : str
        A phase method.

    Returns
    -------
    str
    """
    return "tv" if method == "multislice" else method


def merge_settings(data: dict, changes: dict) -> dict:
    """Reconstruction settings (as a dict) with ``changes`` applied: the one place where the
    command line, napari's widgets and :meth:`RunConfig.of` change settings.

    A top-level key is replaced; a method's section is merged key by key; the section ``'*'`` is
    the chosen method's own (the one that holds its Tikhonov α, :func:`alpha_section`), resolved
    after ``method`` itself has changed.

    Parameters
    ----------
    data : dict
        ``ReconstructionSettings.to_dict()`` (or a file's ``reconstruction:`` section).
    changes : dict
        Keys and sections to change.

    Returns
    -------
    dict
        A new dict; validate it with ``ReconstructionSettings.from_dict``.
    """
    out = dict(data)
    star: dict = {}
    for key, value in changes.items():
        if key == "*":
            star.update(value)
        elif isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = {**out[key], **value}
        else:
            out[key] = value
    if star:
        section = alpha_section(str(out.get("method", "tv")))
        out[section] = {**(out.get(section) or {}), **star}
    return out


def _alpha(default: float, scale: str) -> Any:
    return bounded(default, 1e-8, 1e6, f"Tikhonov regularisation, relative to {scale}")


class WotfSettings(SettingsModel):
    """The 'wotf' method: 3D Tikhonov inversion of all views' weak-object transfer functions."""

    #: Keys read at every solve: changing them keeps the built operators.
    runtime: ClassVar[frozenset[str]] = frozenset()

    alpha: float = _alpha(0.1, "the strongest frequency's Σ_k,z |A|² / K (docs/validation.md)")


class TvSettings(SettingsModel):
    """The 'tv' method: the same operators with total variation and the physical constraints."""

    #: Keys read at every solve: changing them keeps the built operators.
    runtime: ClassVar[frozenset[str]] = frozenset(
        {"sign", "dn_max", "lambda_scale", "iterations", "warm_iterations", "temporal_weight"}
    )

    alpha: float = _alpha(0.1, "the strongest frequency's Σ_k,z |A|² / K: the Tikhonov start")
    sign: Sign = Field("auto", description="sign of Δn against the medium; auto: the one the data support")
    dn_max: float = bounded(0.3, 1e-3, 2.0, "largest |Δn| the sample may have")
    lambda_scale: float | None = bounded(
        None, 1e-3, 1e3, "TV weight relative to the noise-based choice; empty: automatic (1)"
    )
    iterations: int = bounded(60, 1, 2000, "most ADMM iterations")
    warm_iterations: int = bounded(
        20,
        1,
        2000,
        "most ADMM iterations of a frame that starts where the previous frame's solve ended (at most iterations)",
    )
    temporal_weight: float = bounded(
        0.0,
        0.0,
        100.0,
        "weight of the temporal prior |Δn − previous frame's| of a warm-started series frame, "
        "relative to the sparsity's; 0: none",
    )


class RlSettings(SettingsModel):
    """The 'rl' method (the paper's route) and the directional stacks every method can add."""

    #: Keys read at every solve: changing them keeps the built operators.
    runtime: ClassVar[frozenset[str]] = frozenset({"alpha", "iterations"})

    alpha: float = _alpha(0.01, "the |H_DPC|² scale of paper Eq. 7")
    iterations: int = bounded(15, 1, 500, "Richardson-Lucy iterations (the 'rl' method, DPC and stacks)")
    model: TransferModel = Field("lenslet", description="DPC transfer-function model")


class MultisliceSettings(SettingsModel):
    """The 'multislice' method: the 'tv' solution refined with a multislice model of the views
    (refraction and multiple scattering), for strong objects."""

    #: Keys read at every solve (the model is built per frame, around its objects).
    runtime: ClassVar[frozenset[str]] = frozenset(
        {
            "iterations",
            "source_spacing_na",
            "source_subsamples",
            "substeps",
            "refine",
            "roi_margin_um",
            "medium_edge_um",
        }
        | {"roi_um"}
        | {"tv_weight", "stop_residual_over_noise", "model_error", "unknowns", "support_margin_um", "sphere_start"}
        | {"rest_of_frame"}
    )

    iterations: int = bounded(60, 1, 500, "most gradient iterations of the refinement")
    source_spacing_na: float = bounded(
        0.03, 0.005, 0.5, "spacing of the model's source points over the condenser disk, NA units"
    )
    source_subsamples: int = bounded(
        3, 1, 8, "sub-points per source point and axis at the apertures (their sharp edges sampled finer)"
    )
    substeps: int = bounded(1, 1, 8, "multislice slabs per plane")
    refine: int = bounded(
        2, 1, 4, "model samples per view pixel along x and y (2: the light a strong object bends stays in band)"
    )
    roi_margin_um: float = bounded(12.0, 0.0, 500.0, "margin of the model's region around the objects, µm")
    medium_edge_um: float = bounded(
        6.0,
        0.0,
        250.0,
        "band along the region's edge held at the medium (Δn 0), µm: ties every plane's mean to the medium",
    )
    roi_um: list[float] | None = Field(
        None, description="region the model covers, [x_min, x_max, y_min, y_max] µm; empty: around the objects"
    )
    tv_weight: float = bounded(0.0, 0.0, 1e3, "total-variation weight, relative to the views' noise; 0: none")
    unknowns: Literal["views", "model"] = Field(
        "model", description="grid of the fitted Δn: the model's k x k finer samples, or the views' pixels"
    )
    stop_residual_over_noise: float = bounded(
        3.0,
        0.0,
        1e6,
        "stop when the mean squared residual falls to this many times the noise variance (plus the "
        "model's share, model_error)",
    )
    model_error: float = bounded(
        0.04,
        0.0,
        0.5,
        "rms error of the model's views relative to their contrast: the stop is raised by its share "
        "(model_error² x the views' mean squared contrast)",
    )
    support_margin_um: float = bounded(
        0.0,
        0.0,
        100.0,
        "a second fit held to the first fit's objects grown by this margin, µm (their Δn elsewhere at the "
        "medium); 0: none",
    )

    sphere_start: bool = Field(
        True,
        description="when the model does not explain the 'tv' answer, fit its objects as spheres (the bead fit) for "
        "a second start, taken when it explains the views better",
    )
    rest_of_frame: bool = Field(
        True,
        description="when the fit replaced the 'tv' answer in its region, solve the rest of the frame again by 'tv' "
        "with the region's modelled views taken out (outside the region, and added inside it)",
    )

    @model_validator(mode="before")
    @classmethod
    def _retired(cls, data: Any) -> Any:
        """Drop ``z_margin_um`` of older files: the model now covers every plane (no depth windows)."""
        if isinstance(data, dict) and "z_margin_um" in data:
            data = {k: v for k, v in data.items() if k != "z_margin_um"}
        return data

    @model_validator(mode="after")
    def _roi(self) -> MultisliceSettings:
        r = self.roi_um
        if r is not None and (len(r) != 4 or not (r[0] < r[1] and r[2] < r[3])):
            raise ValueError(f"roi_um must be [x_min, x_max, y_min, y_max] with min < max, got {r}")
        return self


#: Keys of files written before the method sections: flat key -> (section, key).
_FLAT_KEYS = {
    "rl_iterations": ("rl", "iterations"),
    "model": ("rl", "model"),
    "sign": ("tv", "sign"),
    "dn_max": ("tv", "dn_max"),
    "tv_lambda": ("tv", "lambda_scale"),
    "tv_iterations": ("tv", "iterations"),
}


class ReconstructionSettings(SettingsModel):
    """How to reconstruct: the z grid (µm), the phase method and its section, the device."""

    #: Keys read at every frame: changing them keeps the built operators.
    runtime: ClassVar[frozenset[str]] = frozenset({"refraction_increment_um3_pg", "warm_start"})

    z_min_um: float = bounded(DEFAULT_Z_UM[0], -5000.0, 5000.0, "first plane, µm from the focal plane (z > 0: farther)")
    z_max_um: float = bounded(DEFAULT_Z_UM[1], -5000.0, 5000.0, "last plane, µm from the focal plane")
    dz_um: float = bounded(1.0, 0.05, 100.0, "plane spacing, µm")
    method: MethodName = Field("tv", description="phase method (docs/validation.md compares them)")
    refraction_increment_um3_pg: float = bounded(
        0.19, 0.05, 0.5, "specific refraction increment for the dry mass, µm³/pg"
    )
    device: Literal["cpu", "gpu"] = Field("cpu", description="cpu (NumPy) or gpu (CuPy, napari-ssdpc[gpu])")
    warm_start: bool = Field(
        True, description="start each frame of a series where the previous frame's solve ended (serial runs)"
    )
    tv: TvSettings = Field(default_factory=TvSettings, description="the 'tv' method")
    wotf: WotfSettings = Field(default_factory=WotfSettings, description="the 'wotf' method")
    rl: RlSettings = Field(default_factory=RlSettings, description="the 'rl' method and the directional stacks")
    multislice: MultisliceSettings = Field(
        default_factory=MultisliceSettings, description="the 'multislice' method (strong objects)"
    )

    @model_validator(mode="before")
    @classmethod
    def _sections(cls, data: Any) -> Any:
        """Read the flat keys of older files into the method sections."""
        if not isinstance(data, dict) or not (set(data) & {*_FLAT_KEYS, "tikhonov_alpha"}):
            return data
        data = dict(data)
        sections: dict[str, dict] = {s: dict(data.get(s) or {}) for s in PHASE_METHODS}
        for key, (section, name) in _FLAT_KEYS.items():
            if key in data:
                sections[section].setdefault(name, data.pop(key))
        alpha = data.pop("tikhonov_alpha", None)
        if alpha is not None:  # it was the chosen method's alpha
            sections[alpha_section(str(data.get("method", "tv")))].setdefault("alpha", alpha)
        data.update({s: v for s, v in sections.items() if v or s in data})
        return data

    @model_validator(mode="after")
    def _z_grid(self) -> ReconstructionSettings:
        if self.z_max_um < self.z_min_um:
            raise ValueError(
                f"z range is empty: z_max_um {self.z_max_um} < z_min_um {self.z_min_um}; give ZMIN <= ZMAX"
            )
        planes = plane_count(self.z_min_um, self.z_max_um, self.dz_um)
        if planes > MAX_PLANES:
            raise ValueError(
                f"{planes} planes from z {self.z_min_um:g} to {self.z_max_um:g} µm every {self.dz_um:g} µm "
                f"(at most {MAX_PLANES}); narrow the z range or take a larger dz_um"
            )
        return self

    @property
    def planes(self) -> int:
        """Planes of the z grid."""
        return plane_count(self.z_min_um, self.z_max_um, self.dz_um)

    @property
    def section(self) -> WotfSettings | TvSettings | RlSettings | MultisliceSettings:
        """The chosen method's own section."""
        section: WotfSettings | TvSettings | RlSettings | MultisliceSettings = getattr(self, self.method)
        return section

    @property
    def alpha(self) -> float:
        """The chosen method's Tikhonov alpha (the multislice method starts from the tv section's)."""
        return float(getattr(self, alpha_section(self.method)).alpha)

    def operator_key(self) -> dict:
        """The settings the operators are built from (the runtime keys of every section left out).

        Returns
        -------
        dict
            Two settings with equal keys can share one Reconstructor.
        """
        data = {k: v for k, v in self.to_dict().items() if k not in self.runtime}
        for name in PHASE_METHODS:
            section = getattr(self, name)
            data[name] = {k: v for k, v in data[name].items() if k not in section.runtime}
        return data

    def with_section(self, method: str | None = None, **changes: Any) -> ReconstructionSettings:
        """A validated copy with keys of a method's section changed.

        Parameters
        ----------
        method : str, optional
            The section ('tv', 'wotf' or 'rl'); default the chosen method's.
        **changes
            Keys of that section.

        Returns
        -------
        ReconstructionSettings
        """
        name = method or self.method
        data = self.to_dict()
        data[name] = {**data[name], **changes}
        return type(self).from_dict(data, source=f"{name} settings")
