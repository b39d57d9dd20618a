"""Imperfections of real instruments, for testing calibration and reconstruction.

Real microlens arrays are not perfect lattices and real frames are not clean white
disks. ``ArrayErrors`` moves every lenslet off its ideal lattice site (a random offset
per lenslet and a shear between the two lattice axes), consistently for both the EI
position on the sensor and the sub-aperture u_k it cuts from the pupil. The functions
below degrade a rendered intensity image (intensity unit of ``camera.py``) the way
instruments do: a lens-mount shadow notching every EI rim, sample content inside every
EI and vignetting across the sensor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import mla_to_frequency
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.settings.lenslets import Lenslet, circle_overlap_fraction, lattice_cell
from napari_ssdpc.settings.optics import Optics


@dataclass(frozen=True)
class ArrayErrors:
    """Manufacturing and mounting errors of a microlens array.

    Parameters
    ----------
    offset_frac : float
        Largest offset of a lenslet from its lattice site, as a fraction of the pitch
        (uniform in a disk of that radius, drawn per lenslet from ``seed``).
    shear_deg : float
        Deviation of the angle between the two lattice axes from 90°: the row axis is
        tilted by this angle, so lenslet (row, col) moves by ``row tan(shear)`` pitches
        along the column axis.
    seed : int
        Seed of the per-lenslet offsets (the same lenslet gets the same offset in every frame).
    """

    offset_frac: float = 0.0
    shear_deg: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.offset_frac < 0.25:
            raise SsdpcError(f"ArrayErrors.offset_frac must be in [0, 0.25), got {self.offset_frac}")
        if not abs(self.shear_deg) < 10:
            raise SsdpcError(f"ArrayErrors.shear_deg must be within ±10°, got {self.shear_deg}")

    def offset_px(self, grid: Grid, row: int, col: int) -> np.ndarray:
        """Displacement (x, y) px of lenslet (row, col) from its ideal lattice site.

        Parameters
        ----------
        grid : Grid
            The nominal array on the sensor (pitch, rotation, lattice).
        row, col : int
            Lattice indices of the lenslet.

        Returns
        -------
        ndarray, float64, (2,)
            (x, y) on the sensor, px.
        """
        rng = np.random.default_rng([self.seed, row + 10_000, col + 10_000])
        r = self.offset_frac * grid.pitch_px * math.sqrt(rng.uniform())
        phi = rng.uniform(0, 2 * math.pi)
        y_ideal = (row + 0.5) * lattice_cell(grid.lattice)[1, 1] * grid.pitch_px  # the row's height
        shear = np.array([y_ideal * math.tan(math.radians(self.shear_deg)), 0.0])
        return grid.matrix @ shear + r * np.array([math.cos(phi), math.sin(phi)])

    def apply(self, grid: Grid, lenslets: list[Lenslet], optics: Optics) -> tuple[list[Lenslet], np.ndarray]:
        """The lenslets as built: moved a_um, u and fraction, and their EI centres (K, 2) px.

        Lenslets that no longer overlap the pupil keep a fraction of 0 (they stay dark).

        Parameters
        ----------
        grid : Grid
            The nominal array on the sensor.
        lenslets : list of Lenslet
            The K lenslets at their ideal lattice sites.
        optics : Optics

        Returns
        -------
        lenslets : list of Lenslet
            The moved lenslets, same order.
        centres : ndarray, (K, 2)
            EI centres (x, y), px.
        """
        um_per_px = optics.pitch_um / grid.pitch_px
        moved, centres = [], []
        for ln in lenslets:
            d = self.offset_px(grid, ln.row, ln.col)
            a = np.asarray(ln.a_um) + np.linalg.solve(grid.matrix, d) * um_per_px
            u = mla_to_frequency(optics, a)
            frac = float(circle_overlap_fraction(math.hypot(*a), optics.lenslet_radius_um, optics.pupil_radius_mla_um))
            moved.append(replace(ln, a_um=(float(a[0]), float(a[1])), u=(float(u[0]), float(u[1])), fraction=frac))
            centres.append(grid.lattice_px(ln.row, ln.col) + d)
        return moved, np.array(centres).reshape(-1, 2)


def _polar(shape, centre):
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(float)
    return np.hypot(xx - centre[0], yy - centre[1]), np.arctan2(yy - centre[1], xx - centre[0])


def notch(intensity, centres_px, radius_px, *, angle_deg=60.0, width_deg=30.0, depth_frac=0.25, dim=0.9):
    """Dark notch at the rim of every EI: the shadow of a lens mount.

    Parameters
    ----------
    intensity : ndarray (H, W)
        Rendered frame, intensity unit.
    centres_px : array_like (K, 2)
        EI centres (x, y), px.
    radius_px : float
        EI radius, px.
    angle_deg, width_deg : float
        Direction of the notch from the EI centre (from +x toward +y) and its angular width.
    depth_frac : float
        How far the shadow reaches into the EI, as a fraction of the radius.
    dim : float
        Fraction of the light the shadow removes.

    Returns
    -------
    ndarray (H, W) float64
        Intensity unit.
    """
    out = np.array(intensity, dtype=np.float64)
    r = radius_px * 1.3
    for cx, cy in np.asarray(centres_px, float):
        x0, x1 = max(int(cx - r), 0), min(int(cx + r) + 2, out.shape[1])
        y0, y1 = max(int(cy - r), 0), min(int(cy + r) + 2, out.shape[0])
        if x0 >= x1 or y0 >= y1:
            continue
        rho, phi = _polar((y1 - y0, x1 - x0), (cx - x0, cy - y0))
        dphi = np.angle(np.exp(1j * (phi - math.radians(angle_deg))))
        inside = (np.abs(dphi) < 0.5 * math.radians(width_deg)) & (rho > (1 - depth_frac) * radius_px)
        out[y0:y1, x0:x1][inside] *= 1 - dim
    return out


def content(intensity, centres_px, radius_px, *, contrast=1.0, parallax_px=3.0, seed=0):
    """Bright sample content in every EI: the same random texture of blobs (cells, debris)
    in each EI, shifted by a parallax that grows with the EI's distance from the array centre.

    ``contrast`` 1 makes the brightest blobs twice as bright as the empty field. Returns a
    float64 image of the same shape.

    Parameters
    ----------
    intensity : ndarray, (H, W)
        Rendered frame, intensity unit.
    centres_px : ndarray, (K, 2)
        EI centres (x, y), px.
    radius_px : float
        EI radius, px.
    contrast : float
        Relative brightness the blobs add (unitless).
    parallax_px : float
        Parallax per x extent of the EI centres: an EI shifts by ``parallax_px`` times its
        offset from their mean divided by that extent, px.
    seed : int
        Seed of the texture.

    Returns
    -------
    ndarray, float64, (H, W)
        Intensity unit.
    """
    out = np.array(intensity, dtype=np.float64)
    rng = np.random.default_rng(seed)
    n = int(2 * radius_px) + 1
    tex = ndimage.gaussian_filter(rng.standard_normal((n, n)), max(1.0, 0.08 * radius_px))
    tex = np.clip(tex / (3 * tex.std()), 0, None) * contrast
    c = np.asarray(centres_px, float)
    mid = c.mean(axis=0)
    half = (n - 1) / 2
    for cx, cy in c:
        shift = (np.array([cx, cy]) - mid) / max(np.ptp(c[:, 0]), 1.0) * parallax_px
        x0, x1 = max(int(cx - half), 0), min(int(cx + half) + 1, out.shape[1])
        y0, y1 = max(int(cy - half), 0), min(int(cy + half) + 1, out.shape[0])
        if x0 >= x1 or y0 >= y1:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1].astype(float)
        t = ndimage.map_coordinates(
            tex, [yy - cy + half - shift[1], xx - cx + half - shift[0]], order=1, mode="constant"
        )
        out[y0:y1, x0:x1] *= 1 + t
    return out


def vignetting(intensity, strength=0.5):
    """Brightness falling off across the sensor as ``1 - strength (r / r_corner)²`` about its centre.

    Parameters
    ----------
    intensity : ndarray, (H, W)
        Rendered frame, intensity unit.
    strength : float
        Relative drop at the sensor corners (unitless).

    Returns
    -------
    ndarray, float64, (H, W)
        Intensity unit.
    """
    out = np.array(intensity, dtype=np.float64)
    rho, _ = _polar(out.shape, ((out.shape[1] - 1) / 2, (out.shape[0] - 1) / 2))
    return out * (1 - strength * (rho / rho.max()) ** 2)
