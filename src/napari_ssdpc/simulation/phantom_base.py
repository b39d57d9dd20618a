"""The base of every phantom: a sum of primitives, its analytic Δn and its voxelisers.

:class:`Phantom` turns the primitives of a subclass (:mod:`.primitives`) into Δn(z, y, x), the
phantom's extent and two partial-volume voxelisers (``slab``: ∫ Δn dz over pixels; ``volume``:
voxel averages); :class:`Composite` is any sum of primitives. The samples themselves (beads, the
cell, the bar target, the moving sample) are in :mod:`.phantoms`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from napari_ssdpc.errors import SsdpcError

__all__ = ["Composite", "Phantom"]


class Phantom:
    """Base class: a sum of primitives with Δn relative to the medium.

    Attributes
    ----------
    medium_index : float or None
        The phantom's own medium; None: the optics' medium.
    needs_medium : bool
        False when Δn is given relative to any medium (``Composite``, ``BarTarget``).
    """

    medium_index: float | None = None
    needs_medium = True  # False: Δn is given relative to any medium (Composite, BarTarget)

    def parts(self, medium_index: float) -> list:
        """The primitives of the phantom, with Δn against ``medium_index``.

        Parameters
        ----------
        medium_index : float
            Index of the medium (Δn of each part is taken against it).

        Returns
        -------
        list of Ellipsoid or Box
        """
        raise NotImplementedError

    def medium(self, medium_index=None) -> float:
        """The medium the phantom sits in.

        Parameters
        ----------
        medium_index : float, optional
            Used when the phantom has none of its own.

        Returns
        -------
        float
            The phantom's own medium index, else ``medium_index`` (NaN for a phantom given as Δn).
        """
        n = self._any_medium(medium_index)
        if n is None and not self.needs_medium:
            return float("nan")
        if n is None:
            raise SsdpcError(
                f"{type(self).__name__} has no medium_index; pass medium_index=... "
                "(or use Simulation.phantom, which the simulator binds to the optics' medium)"
            )
        return float(n)

    def with_medium(self, medium_index: float) -> Phantom:
        """A copy bound to ``medium_index`` (kept if the phantom already has one).

        Parameters
        ----------
        medium_index : float

        Returns
        -------
        Phantom
        """
        if self.medium_index is not None:
            return self
        return replace(self, medium_index=float(medium_index))

    def _parts(self, medium_index=None):
        return self.parts(self.medium(medium_index))

    def delta_n(self, z, y, x, medium_index=None) -> np.ndarray:
        """Analytic complex Δn at points (z, y, x) µm (broadcast).

        Parameters
        ----------
        z, y, x : array_like
            Positions, µm (broadcast together).
        medium_index : float, optional
            Used when the phantom has none of its own.

        Returns
        -------
        ndarray, complex128
            Δn (imaginary part: absorption index κ), the broadcast shape.
        """
        shape = np.broadcast_shapes(np.shape(z), np.shape(y), np.shape(x))
        out = np.zeros(shape, dtype=np.complex128)
        for p in self._parts(medium_index):
            out += p.delta_n(z, y, x)
        return out

    def z_range(self, medium_index=1.0) -> tuple[float, float]:
        """(z_min, z_max) µm of the sample (the z extent).

        Parameters
        ----------
        medium_index : float
            Used to build the parts when the phantom has no medium of its own.

        Returns
        -------
        (float, float)
            z_min, z_max, µm.
        """
        rs = [p.z_range() for p in self.parts(self._any_medium(medium_index))]
        return min(r[0] for r in rs), max(r[1] for r in rs)

    def xy_box(self, medium_index=1.0) -> tuple[float, float, float, float]:
        """Lateral bounding box (x_min, x_max, y_min, y_max) µm.

        Parameters
        ----------
        medium_index : float
            Used to build the parts when the phantom has no medium of its own.

        Returns
        -------
        (float, float, float, float)
            x_min, x_max, y_min, y_max, µm.
        """
        bs = [p.xy_box() for p in self.parts(self._any_medium(medium_index))]
        return (min(b[0] for b in bs), max(b[1] for b in bs), min(b[2] for b in bs), max(b[3] for b in bs))

    def _any_medium(self, medium_index):
        return self.medium_index if self.medium_index is not None else medium_index

    def slab(self, z0, z1, y, x, pixel_um, medium_index=None, supersample=4) -> np.ndarray:
        """∫ Δn dz over [z0, z1] (µm), averaged over pixels of side ``pixel_um``.

        Parameters
        ----------
        z0, z1 : float
            Slab bounds, µm.
        y, x : ndarray, 1D
            Pixel centres, µm, ascending.
        pixel_um : float
            Pixel side, µm.
        medium_index : float, optional
            Used when the phantom has none of its own.
        supersample : int
            Sub-samples per pixel side.

        Returns
        -------
        ndarray, complex128, (len(y), len(x))
            ∫ Δn dz per pixel, µm.
        """
        out = np.zeros((len(y), len(x)), dtype=np.complex128)
        for p in self._parts(medium_index):
            out += p.slab(z0, z1, y, x, pixel_um, supersample)
        return out

    def volume(self, z_um, y_um, x_um, medium_index=None, supersample=4) -> np.ndarray:
        """Partial-volume voxel averages of Δn on the regular grid (z, y, x), complex.

        Parameters
        ----------
        z_um, y_um, x_um : ndarray, 1D
            Voxel centres, µm, evenly spaced (the same spacing in y and x).
        medium_index : float, optional
            Used when the phantom has none of its own.
        supersample : int
            Lateral sub-samples per voxel side.

        Returns
        -------
        ndarray, complex128, (Z, Y, X)
            Voxel-averaged Δn (imaginary part: absorption index κ).
        """
        z, y, x = (np.asarray(v, dtype=float) for v in (z_um, y_um, x_um))
        dz = float(z[1] - z[0]) if len(z) > 1 else 1.0
        dx = float(x[1] - x[0]) if len(x) > 1 else 1.0
        dy = float(y[1] - y[0]) if len(y) > 1 else dx
        if not math.isclose(dx, dy, rel_tol=1e-6):
            raise SsdpcError("volume() needs the same x and y spacing; resample one axis")
        return np.stack([self.slab(zi - dz / 2, zi + dz / 2, y, x, dx, medium_index, supersample) / dz for zi in z])


@dataclass(frozen=True)
class Composite(Phantom):
    """Any sum of primitives (``Ellipsoid``, ``Box``) whose ``dn`` is already relative to the medium.

    Attributes
    ----------
    items : tuple of Ellipsoid or Box
    medium_index : float or None
        The medium, or None: the optics'.
    """

    items: tuple = ()
    medium_index: float | None = None
    needs_medium = False

    def parts(self, medium_index):
        """The primitives (see :meth:`Phantom.parts`).

        Parameters
        ----------
        medium_index : float
            Unused: the items' Δn is already relative to the medium.

        Returns
        -------
        list of Ellipsoid or Box
            ``items``.
        """
        if not self.items:
            raise SsdpcError("Composite phantom is empty; give it Ellipsoid/Box items")
        return list(self.items)
