"""Phase (2D) or Δn (3D) from a conventional DPC stack, through the same phase methods as the
light-field frames: the front end :class:`~napari_ssdpc.reconstruction.led_views.LedViews` hands
them its views and models (docs/dpc.md).

- One image per pattern (``z_um`` left out): the phase of the sample in its focal plane, rad, from
  one slab (the images see the whole sample's projected phase).
- A z-stack per pattern: Δn on planes from the stack's first to its last focal plane every
  ``dz_um`` (default the stack's own spacing), each slab through its defocused transfer functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from napari_ssdpc.backend import get_backend
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.frame_result import z_grid
from napari_ssdpc.reconstruction.led_views import MULTISLICE_2D, LedViews
from napari_ssdpc.reconstruction.methods import method_class
from napari_ssdpc.reconstruction.methods.base import Setup
from napari_ssdpc.settings.dpc_optics import DpcOptics
from napari_ssdpc.settings.reconstruction import ReconstructionSettings, TvSettings

__all__ = [
    "DPC_ALPHA",
    "DPC_METHODS",
    "STACK_ITERATIONS",
    "STACK_MULTISLICE",
    "DpcResult",
    "dpc_settings",
    "reconstruct_dpc",
]

#: The phase methods a DPC stack takes, by the names ``ssdpc dpc`` gives them: 'tikhonov' is the
#: registry's linear 'wotf' inversion (paper Eq. 7 for K images and Z slabs).
DPC_METHODS = {"tikhonov": "wotf", "tv": "tv", "multislice": "multislice"}

#: Tikhonov α of DPC stacks, relative to the strongest frequency's Σ_k |H_k|² / K: with four half-disks
#: at σ = 1 it is the absolute 0.005 of the Waller-Lab DPC example (docs/dpc.md).
DPC_ALPHA = 0.015

#: Most 'tv' iterations of a z-stack: the four halves' 3D transfer functions leave the lowest axial
#: frequencies weakly measured, and 60 iterations leave a floor of Δn over the field (2.5 µm beads at
#: NA 0.65: masses 1.10-1.22 after 60, 1.05-1.09 when it converged after 172; docs/dpc.md).
STACK_ITERATIONS = 200

#: The multislice model of a z-stack: the whole illumination disk (σ up to 1) holds many more source
#: points than a light-field condenser's, and every image is a view: points 0.1 NA apart without
#: sub-points, the views' own pixels, a region 3 µm around the objects, no bead fit (each of its
#: evaluations is a whole model's). A 2.5 µm bead of Δn 0.05 in 48 x 48 px, 9 planes: 30
#: iterations in 25 s on 2 cores, its mass 1.39 -> 1.10 of the truth (docs/dpc.md).
STACK_MULTISLICE = {
    "source_spacing_na": 0.1,
    "source_subsamples": 1,
    "refine": 1,
    "roi_margin_um": 3.0,
    "medium_edge_um": 1.0,
    "sphere_start": False,
    "iterations": 30,
}

#: A 2D image's one slab: its thickness only scales the phase bound of 'tv' (Δn_max · 2π dz / λ).
SLAB_2D_UM = 1.0


@dataclass
class DpcResult:
    """What a DPC stack gave.

    Attributes
    ----------
    phase : ndarray, float32, (ny, nx) or None
        2D: the phase, rad.
    delta_n : ndarray, float32, (Z, ny, nx) or None
        3D: Δn against the medium on the planes ``z_um``.
    z_um : ndarray, (Z,)
        The planes, µm (``[0]`` in 2D).
    dz_um : float
        Their spacing (the slab thickness), µm.
    pixel_um : float
        Object-side pixel, µm.
    method : str
        The method's name as ``ssdpc dpc`` gives it.
    report : dict
        What the method did (its plain numbers).
    """

    phase: np.ndarray | None
    delta_n: np.ndarray | None
    z_um: np.ndarray
    dz_um: float
    pixel_um: float
    method: str
    report: dict = field(default_factory=dict)


def dpc_settings(optics: DpcOptics, *, alpha=None, sign=None, iterations=None) -> ReconstructionSettings:
    """The methods' sections for a DPC stack: its own defaults where a value is not given.

    Parameters
    ----------
    optics : DpcOptics
    alpha : float, optional
        Tikhonov α (of 'tikhonov' and of the start of 'tv'), relative; default :data:`DPC_ALPHA`.
    sign : {'auto', 'denser', 'lighter', 'any'}, optional
        'tv': the sign of Δn; default 'any' for one image a pattern (a 2D phase has lost its lowest
        frequencies: no sign holds everywhere), 'auto' for a z-stack.
    iterations : int, optional
        'tv': most iterations; default :data:`STACK_ITERATIONS` for a z-stack, the 'tv' section's for 2D.

    Returns
    -------
    ReconstructionSettings
    """
    a = DPC_ALPHA if alpha is None else alpha
    tv: dict = {"alpha": a, "sign": sign or ("auto" if optics.is_stack else "any")}
    tv["iterations"] = iterations or (STACK_ITERATIONS if optics.is_stack else TvSettings().iterations)
    if not optics.is_stack:
        tv["dn_max"] = 2.0  # the one slab's bound Δn_max·2π·dz/λ does not limit a 2D phase
    sections = {"wotf": {"alpha": a}, "tv": tv, "multislice": STACK_MULTISLICE}
    return ReconstructionSettings.from_dict(sections, source="DPC settings")


def settings_for(
    optics: DpcOptics, method: str, settings: ReconstructionSettings | None = None, **z
) -> ReconstructionSettings:
    """The reconstruction settings of a stack: its z grid and the registry's method.

    Parameters
    ----------
    optics : DpcOptics
    method : {'tikhonov', 'tv', 'multislice'}
    settings : ReconstructionSettings, optional
        Sections to keep (``tv``, ``wotf``, ...); default :func:`dpc_settings`.
    **z
        ``z_min_um``, ``z_max_um``, ``dz_um`` of a 3D stack (default: its focal planes and their spacing).

    Returns
    -------
    ReconstructionSettings
    """
    if method not in DPC_METHODS:
        raise SsdpcError(f"unknown DPC method '{method}'; use one of {', '.join(DPC_METHODS)}")
    if method == "multislice" and not optics.is_stack:
        raise SsdpcError(MULTISLICE_2D)
    base = (settings or dpc_settings(optics)).to_dict()
    if optics.is_stack:
        planes = sorted(optics.focal_planes_um)
        steps = np.diff(planes)
        dz = float(np.min(steps)) if len(steps) else optics.depth_of_field_um / 2
        grid = {"z_min_um": planes[0], "z_max_um": planes[-1], "dz_um": dz}
        grid.update({k: float(v) for k, v in z.items() if v is not None})
    else:
        if any(v is not None for v in z.values()):
            raise SsdpcError("a z range is for z-stacks; give z_um in the optics file, or leave the z range out")
        grid = {"z_min_um": 0.0, "z_max_um": 0.0, "dz_um": SLAB_2D_UM}
    return ReconstructionSettings.from_dict({**base, **grid, "method": DPC_METHODS[method]}, source="DPC settings")


def reconstruct_dpc(
    stack,
    optics: DpcOptics,
    method: str = "tv",
    *,
    settings: ReconstructionSettings | None = None,
    progress=None,
    **z,
) -> DpcResult:
    """Reconstruct a DPC stack with one of the phase methods.

    Parameters
    ----------
    stack : array_like, (P, ny, nx) or (P, F, ny, nx)
        One image per pattern of ``optics.patterns_deg`` (a z-stack per pattern in the order of
        ``optics.z_um``), camera units.
    optics : DpcOptics
    method : {'tikhonov', 'tv', 'multislice'}
    settings : ReconstructionSettings, optional
        The methods' sections (``wotf.alpha``, ``tv.sign``, ...; default :func:`dpc_settings`); the
        z grid comes from the stack.
    progress : callable, optional
        ``progress(done, total, label)``.
    **z
        ``z_min_um``, ``z_max_um``, ``dz_um`` for a 3D stack.

    Returns
    -------
    DpcResult
    """
    a = np.asarray(stack)
    if a.ndim < 3:
        raise SsdpcError(f"a DPC stack has one image per pattern, got an array of shape {a.shape}")
    s = settings_for(optics, method, settings, **z)
    views = LedViews(optics, a.shape[-2:])
    data = views(a)
    z_um = z_grid(s.z_min_um, s.z_max_um, s.dz_um)
    setup = Setup(optics, s, views, z_um, get_backend(s.device))
    built = method_class(s.method).build(setup, progress)
    sol = built.solve(data, progress=progress)
    if optics.is_stack:
        dn = sol.phase * (optics.wavelength_um / (2 * math.pi * s.dz_um))  # Δn = λφ/(2π dz)
        return DpcResult(None, dn.astype(np.float32), z_um, s.dz_um, views.pixel_um, method, dict(sol.report))
    return DpcResult(sol.phase[0], None, z_um, s.dz_um, views.pixel_um, method, dict(sol.report))
