"""What a reconstruction gives for one frame (:class:`Result`) and the planes it is made on (:func:`z_grid`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.methods.base import Solution
from napari_ssdpc.settings.outputs import QUANTITIES, layout
from napari_ssdpc.settings.reconstruction import MAX_PLANES, plane_count

__all__ = ["Result", "z_grid"]


def z_grid(z_min_um: float, z_max_um: float, dz_um: float) -> np.ndarray:
    """Planes from z_min to z_max (inclusive) every dz µm.

    Parameters
    ----------
    z_min_um, z_max_um : float
        First and last plane, µm from the focal plane.
    dz_um : float
        Spacing, µm.

    Returns
    -------
    ndarray, float64, (Z,)
    """
    if not all(isinstance(v, (int, float, np.number)) and math.isfinite(v) for v in (z_min_um, z_max_um, dz_um)):
        raise SsdpcError(f"z from {z_min_um!r} to {z_max_um!r} every {dz_um!r} µm: give finite numbers")
    if not dz_um > 0:
        raise SsdpcError(f"dz must be > 0 µm, got {dz_um}")
    if z_max_um < z_min_um:
        raise SsdpcError(f"z range is empty: z_max {z_max_um} < z_min {z_min_um}; give --z ZMIN ZMAX with ZMIN <= ZMAX")
    n = plane_count(z_min_um, z_max_um, dz_um)
    if n > MAX_PLANES:
        raise SsdpcError(f"{n} planes from z {z_min_um} to {z_max_um} µm every {dz_um} µm (at most {MAX_PLANES})")
    return (z_min_um + dz_um * np.arange(n)).astype(np.float64)


@dataclass
class Result:
    """Reconstruction of one frame. Arrays are (z, y, x) with coordinates in µm."""

    ri: np.ndarray
    delta_n: np.ndarray
    phase: np.ndarray
    absorption: np.ndarray | None
    dpc: dict
    stacks: dict
    z_um: np.ndarray
    y_um: np.ndarray
    x_um: np.ndarray
    convergence: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    solution: Solution | None = None

    @property
    def voxel_um(self) -> tuple[float, float, float]:
        """(dz, dy, dx) in µm; dz of a single plane is the slab thickness it was made with."""
        dz = float(self.z_um[1] - self.z_um[0]) if len(self.z_um) > 1 else float(self.settings.get("dz_um", 1.0))
        return dz, float(self.y_um[1] - self.y_um[0]), float(self.x_um[1] - self.x_um[0])

    @property
    def projected_phase(self) -> np.ndarray:
        """(y, x) phase summed over the slabs, rad: what a 2D quantitative phase image shows."""
        return np.asarray(np.sum(self.phase, axis=0, dtype=np.float64), np.float32)

    @property
    def opd_nm(self) -> np.ndarray:
        """(y, x) optical path difference Σ_z Δn dz, nm."""
        return np.asarray(1e3 * self.voxel_um[0] * np.sum(self.delta_n, axis=0, dtype=np.float64), np.float32)

    def images(self, save=()) -> dict[str, tuple[np.ndarray, str, str]]:
        """{name: (array, axes, description)}: RI and the quantities asked for, as written.

        Parameters
        ----------
        save : iterable of str
            Registry names beside RI (:data:`~napari_ssdpc.settings.outputs.QUANTITIES`).

        Returns
        -------
        dict
        """
        out = {}
        for name, (_, axes, what) in layout(len(self.z_um), self.phase.shape[1:], save).items():
            data = QUANTITIES[name].of(self)
            if data is None:
                raise SsdpcError(f"the result holds no {name}: reconstruct with the directional stacks")
            out[name] = (data, axes, what)
        return out

    @property
    def dry_mass(self) -> np.ndarray:
        """(y, x) dry-mass surface density OPD / α, pg/µm² (α: the specific refraction increment)."""
        alpha = float(self.settings.get("refraction_increment_um3_pg", 0.19))
        return (1e-3 * self.opd_nm / alpha).astype(np.float32)
