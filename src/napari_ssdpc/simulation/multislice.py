"""Illumination and multislice propagation of the forward simulator.

1. Köhler illumination: the condenser disk is sampled as plane waves ON THE PERIODIC
   FREQUENCY LATTICE of the simulation grid (spacing du = 1 / grid size), every
   ``Source.step`` lattice units, each weighted by the exact area of its lattice cell
   inside the disk (so the total source area is right). Intensities of the source
   points add (Abbe's method; paper Eq. 2).
2. Multislice (beam propagation) through the 3D RI phantom: slabs of thickness
   ≤ ``dz_um`` (0.5 µm), a phase/absorption screen exp(i2π ∫Δn dz / λ) per slab,
   angular-spectrum propagation in the medium between them, exp(+i2π d η(u)),
   η(u) = sqrt((n/λ)² − |u|²) (``physics.waves``, as the source sampling). Empty slabs
   are skipped (one step across a gap). The field is carried as the envelope
   V = U·exp(−i2π w·x) of the tilted wave, on a sub-grid around the phantom, and embedded
   into the full grid afterwards.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.apertures import kohler_source
from napari_ssdpc.physics.waves import apply_transfer, propagator
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.phantoms import (
    Phantom,
    optics_for,
)

DX_UM = 0.3  # lateral sampling of the object grid (µm)
DZ_UM = 0.5  # maximal slab thickness of the multislice (µm)


# --------------------------------------------------------------------------- sampling
@dataclass(frozen=True)
class Sampling:
    """The periodic object-space grid: ``n`` x ``n`` samples of ``dx_um``.

    Its frequency lattice (spacing ``du = 1 / size_um``) carries the source points,
    the pupils and the lenslet sub-apertures.

    Attributes
    ----------
    n : int
        Samples per side (even).
    dx_um : float
        Sample spacing, µm.
    """

    n: int
    dx_um: float

    @classmethod
    def for_optics(cls, optics: Optics, dx_um: float = DX_UM, guard_um: float | None = None) -> Sampling:
        """Grid covering the field of view plus a guard band on each side
        (default max(15 µm, 15 % of the FOV)) for defocus blur and scattering.

        Parameters
        ----------
        optics : Optics
        dx_um : float
            Lateral sampling, µm.
        guard_um : float, optional
            Guard band, µm.

        Returns
        -------
        Sampling
        """
        guard = max(15.0, 0.15 * optics.fov_um) if guard_um is None else float(guard_um)
        if not 0 < dx_um <= 0.5 * optics.wavelength_um / (optics.na + optics.condenser_na):
            raise SsdpcError(
                f"dx_um {dx_um} is too coarse for NA {optics.na}: use <= "
                f"{0.5 * optics.wavelength_um / (optics.na + optics.condenser_na):.3f} µm"
            )
        n = even_fast(math.ceil((optics.fov_um + 2 * guard) / dx_um))
        return cls(n, float(dx_um))

    @property
    def size_um(self) -> float:
        """Side of the grid, µm."""
        return self.n * self.dx_um

    @property
    def du(self) -> float:
        """Frequency step 1/size, cycles/µm."""
        return 1.0 / self.size_um

    def x(self) -> np.ndarray:
        """Sample positions in FFT order (x = 0 at index 0).

        Returns
        -------
        ndarray, float64, (n,)
            µm.
        """
        return np.fft.fftfreq(self.n, 1.0 / self.n) * self.dx_um

    def u(self) -> np.ndarray:
        """Frequencies of the grid (FFT order), cycles/µm.

        Returns
        -------
        ndarray, float64, (n,)
            cycles/µm.
        """
        return np.fft.fftfreq(self.n, self.dx_um)


def even_fast(m: int) -> int:
    """The smallest even FFT-friendly size >= ``m``.

    Parameters
    ----------
    m : int
        Smallest acceptable size.

    Returns
    -------
    int
    """
    m = sfft.next_fast_len(int(m))
    while m % 2:
        m = sfft.next_fast_len(m + 1)
    return m


@dataclass(frozen=True)
class Source:
    """Sampling of the condenser disk on the frequency lattice of the grid.

    ``step``: spacing of the source points in lattice units (du = 1/grid size, 1/162
    cycles/µm for the paper's optics). ``na``: condenser NA (None: the optics'). Each
    point is weighted by the area of its step x step lattice cell inside the disk,
    computed with ``supersample`` x ``supersample`` sub-cells, so the weights sum to
    the disk area.

    Attributes
    ----------
    step : int
        Spacing of the source points, lattice units (du).
    na : float or None
        Condenser NA; None: ``optics.condenser_na``.
    supersample : int
        Sub-cells per cell side for the weights of the cells on the disk's edge.
    """

    step: int = 2
    na: float | None = None
    supersample: int = 64

    def __post_init__(self):
        if int(self.step) < 1 or int(self.step) != self.step:
            raise SsdpcError(f"Source.step must be a positive integer (lattice units), got {self.step}")

    def radius(self, optics: Optics) -> float:
        """The condenser disk's radius on the frequency lattice, cycles/µm.

        Parameters
        ----------
        optics : Optics

        Returns
        -------
        float
        """
        na = optics.condenser_na if self.na is None else float(self.na)
        return na / optics.wavelength_um

    def points(self, optics: Optics, sampling: Sampling):
        """The source points of these optics on the grid's frequency lattice.

        Parameters
        ----------
        optics : Optics
            Its wavelength and condenser NA (unless ``na`` is set) give the disk.
        sampling : Sampling
            Its lattice step ``du`` places the points.

        Returns
        -------
        tuple of ndarray
            ``(idx, w, weights)``: lattice indices (K, 2), frequencies (K, 2) in cycles/µm and
            weights (K,) in (cycles/µm)², as :func:`napari_ssdpc.physics.apertures.kohler_source` gives them.
        """
        return kohler_source(
            self.radius(optics), sampling.du, int(self.step), int(self.supersample), centre=optics.source_centre
        )


# ------------------------------------------------------------------------ multislice
class Slabs:
    """Multislice: the phantom's phase/absorption screens on a sub-grid around it.

    Parameters
    ----------
    phantom : Phantom
        Bound to a medium (:meth:`Phantom.with_medium`).
    optics : Optics
    sampling : Sampling
        The full object grid.
    dz_um : float
        Largest slab thickness, µm.
    supersample : int
        Lateral sub-samples per pixel side of the voxeliser.

    Attributes
    ----------
    ns : int
        Side of the sub-grid, samples (``sampling.n`` when it would not be smaller).
    z : list of float
        Centres of the non-empty slabs, µm, farthest from the objective first.
    screens : list of ndarray, complex64, (ns, ns)
        exp(i2π ∫Δn dz / λ) of each non-empty slab.
    z_exit : float
        Depth of the last screen, µm.
    """

    def __init__(self, phantom: Phantom, optics: Optics, sampling: Sampling, dz_um=DZ_UM, supersample=4):
        lam, nm, dx = optics.wavelength_um, optics.medium_index, sampling.dx_um
        z0, z1 = phantom.z_range()
        nz = max(1, int(math.ceil((z1 - z0) / dz_um - 1e-9)))
        dz = (z1 - z0) / nz
        x0, x1, y0, y1 = phantom.xy_box()
        margin = 10.0 + 0.3 * (z1 - z0)  # room for light scattered within the NA
        ns = even_fast(math.ceil((max(x1 - x0, y1 - y0) + 2 * margin) / dx))
        if ns >= sampling.n:
            ns, ci, cj = sampling.n, 0, 0
        else:
            ci, cj = int(round(0.5 * (y0 + y1) / dx)), int(round(0.5 * (x0 + x1) / dx))
        self.ns, self.full = ns, ns == sampling.n
        if self.full:
            self.rows = self.cols = np.arange(ns)
            yc = xc = sampling.x()
            order = np.argsort(xc)
        else:
            self.rows = (ci + np.arange(ns) - ns // 2) % sampling.n
            self.cols = (cj + np.arange(ns) - ns // 2) % sampling.n
            yc = (ci + np.arange(ns) - ns // 2) * dx
            xc = (cj + np.arange(ns) - ns // 2) * dx
            order = None
        self.z, self.screens = [], []
        for k in range(nz):
            za, zb = z1 - k * dz - dz, z1 - k * dz  # top (far side) first
            if order is None:
                s = phantom.slab(za, zb, yc, xc, dx, supersample=supersample)
            else:  # full grid: evaluate on sorted coordinates, then back to FFT order
                inv = np.argsort(order)
                s = phantom.slab(za, zb, yc[order], xc[order], dx, supersample=supersample)[np.ix_(inv, inv)]
            if np.any(s != 0):
                self.z.append(0.5 * (za + zb))
                self.screens.append(np.exp(2j * np.pi * s / lam).astype(np.complex64))
        if not self.screens:
            raise SsdpcError("the phantom has no non-zero Δn on the simulation grid; check its position and size")
        self.dx, self.lam, self.nm = dx, lam, nm
        self.z_exit = self.z[-1]
        r = max(2, int(round(4.0 / dx)))  # 4 µm cosine taper at the sub-grid rim
        w = np.ones(ns)
        ramp = 0.5 - 0.5 * np.cos(np.pi * (np.arange(r) + 0.5) / r)
        w[:r], w[-r:] = ramp, ramp[::-1]
        self.taper = (w[:, None] * w[None, :]).astype(np.float32)

    def exit_envelope(self, tilt) -> np.ndarray:
        """Envelope V of the exit field (at z_exit) for the plane wave of frequency ``tilt``.

        Parameters
        ----------
        tilt : (float, float)
            Plane-wave frequency w (x, y), cycles/µm.

        Returns
        -------
        ndarray, complex64, (ns, ns)
            V on the sub-grid.
        """
        v = self.screens[0].copy()
        cache = {}
        for k in range(1, len(self.screens)):
            d = round(self.z[k - 1] - self.z[k], 9)
            if d not in cache:
                cache[d] = propagator(self.ns, self.ns, self.dx, d, self.lam, self.nm, tilt)  # H_d, paper Eq. 6
            v = apply_transfer(v, cache[d]) * self.screens[k]
        return v

    def embed(self, v, n) -> np.ndarray:
        """Full-grid envelope: 1 outside the sub-grid, tapered scattered part inside.

        Parameters
        ----------
        v : ndarray, complex, (ns, ns)
            Envelope on the sub-grid (from :meth:`exit_envelope`).
        n : int
            Full grid size.

        Returns
        -------
        ndarray, complex, (n, n)
            Envelope on the full grid, FFT order.
        """
        if self.full:
            return v
        out = np.ones((n, n), dtype=np.complex64)
        out[np.ix_(self.rows, self.cols)] = 1.0 + self.taper * (v - 1.0)
        return out


def exit_field(
    phantom: Phantom, optics: Optics, tilt=(0.0, 0.0), sampling: Sampling | None = None, dz_um: float = DZ_UM
):
    """Multislice exit field of one plane wave (envelope V, ``U = V exp(i2π w·x)``).

    Returns (V on the full grid in FFT order, z_exit µm, sampling). Useful for checks.

    Parameters
    ----------
    phantom : Phantom
        The sample; without a medium of its own it takes the optics'.
    optics : Optics
    tilt : (float, float)
        w (x, y), cycles/µm.
    sampling : Sampling, optional
        Default ``Sampling.for_optics(optics)``.
    dz_um : float
        Largest slab thickness, µm.

    Returns
    -------
    v : ndarray, complex, (n, n)
        Exit envelope V on the full grid, FFT order.
    z_exit : float
        Depth of the exit plane, µm.
    sampling : Sampling
        The grid used.
    """
    phantom = phantom.with_medium(optics.medium_index)
    optics = optics_for(phantom, optics)
    sampling = sampling or Sampling.for_optics(optics)
    slabs = Slabs(phantom, optics, sampling, dz_um)
    v = slabs.embed(slabs.exit_envelope(np.asarray(tilt, float)), sampling.n)
    return v, slabs.z_exit, sampling
