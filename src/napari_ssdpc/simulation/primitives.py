"""The primitives phantoms are made of: an ellipsoid and a box, each with an analytic Δn and
exact partial-volume integrals (see :mod:`.phantoms`). Positions are (x, y, z) in µm."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Box", "Ellipsoid"]


class _Primitive:
    """What the primitives share: Δn from an inside test, the extent from half-widths.

    A subclass has ``center_um`` (x, y, z) µm and ``dn``, and implements ``_inside``,
    ``_half_depth`` and ``_half_widths``.
    """

    center_um: tuple[float, float, float]
    dn: complex

    def _inside(self, z, y, x):
        raise NotImplementedError

    def _half_depth(self) -> float:
        raise NotImplementedError

    def _half_widths(self) -> tuple[float, float]:
        raise NotImplementedError

    def delta_n(self, z, y, x):
        """Δn of the primitive at points (z, y, x) µm.

        Parameters
        ----------
        z, y, x : array_like
            Positions, µm (broadcast together).

        Returns
        -------
        ndarray, complex
            Δn (imaginary part: absorption) at each point.
        """
        z, y, x = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (z, y, x)))
        return np.where(self._inside(z, y, x), complex(self.dn), 0j)

    def z_range(self):
        """z extent of the primitive.

        Returns
        -------
        (float, float)
            z_min, z_max, µm.
        """
        h = self._half_depth()
        return self.center_um[2] - h, self.center_um[2] + h

    def xy_box(self):
        """Lateral bounding box of the primitive.

        Returns
        -------
        (float, float, float, float)
            x_min, x_max, y_min, y_max, µm.
        """
        hx, hy = self._half_widths()
        cx, cy, _ = self.center_um
        return cx - hx, cx + hx, cy - hy, cy + hy


@dataclass(frozen=True)
class Ellipsoid(_Primitive):
    """Ellipsoid with constant complex Δn, semi-axes (a, b, c) along x', y', z;
    x', y' are x, y rotated by ``angle_deg`` about z.

    Attributes
    ----------
    center_um : (float, float, float)
        Centre (x, y, z), µm.
    semi_axes_um : (float, float, float)
        Semi-axes (a, b, c), µm.
    dn : complex
        Δn against the medium; imaginary part: absorption index κ.
    angle_deg : float
        Rotation about z, degrees.
    """

    center_um: tuple[float, float, float]
    semi_axes_um: tuple[float, float, float]
    dn: complex
    angle_deg: float = 0.0

    def _lateral_q(self, y, x):
        cx, cy, _ = self.center_um
        a, b, _ = self.semi_axes_um
        t = math.radians(self.angle_deg)
        dx, dy = x - cx, y - cy
        xr = dx * math.cos(t) + dy * math.sin(t)
        yr = -dx * math.sin(t) + dy * math.cos(t)
        return (xr / a) ** 2 + (yr / b) ** 2

    def _inside(self, z, y, x):
        c, cz = self.semi_axes_um[2], self.center_um[2]
        return self._lateral_q(y, x) + ((z - cz) / c) ** 2 <= 1.0

    def _half_depth(self):
        return self.semi_axes_um[2]

    def _half_widths(self):
        a, b, _ = self.semi_axes_um
        t = math.radians(self.angle_deg)
        return math.hypot(a * math.cos(t), b * math.sin(t)), math.hypot(a * math.sin(t), b * math.cos(t))

    def slab(self, z0, z1, y, x, pixel_um, supersample=4):
        """Pixel-averaged ∫Δn dz over [z0, z1]: exact chord in z, supersampled laterally.

        Parameters
        ----------
        z0, z1 : float
            Slab bounds, µm.
        y, x : ndarray, 1D
            Pixel centres, µm, ascending.
        pixel_um : float
            Pixel side, µm.
        supersample : int
            Sub-samples per pixel side.

        Returns
        -------
        ndarray, complex128, (len(y), len(x))
            ∫ Δn dz per pixel, µm.
        """
        out = np.zeros((len(y), len(x)), dtype=np.complex128)
        zlo, zhi = self.z_range()
        if z1 <= zlo or z0 >= zhi:
            return out
        ys, xs = _window(y, x, self.xy_box(), pixel_um)
        if ys.stop <= ys.start or xs.stop <= xs.start:
            return out
        c, cz = self.semi_axes_um[2], self.center_um[2]
        offs = ((np.arange(supersample) + 0.5) / supersample - 0.5) * pixel_um
        acc = np.zeros((ys.stop - ys.start, xs.stop - xs.start))
        yy, xx = np.asarray(y)[ys], np.asarray(x)[xs]
        for oy in offs:
            for ox in offs:
                q = self._lateral_q((yy + oy)[:, None], (xx + ox)[None, :])
                h = c * np.sqrt(np.clip(1.0 - q, 0.0, None))
                length = np.minimum(z1, cz + h) - np.maximum(z0, cz - h)
                acc += np.where(q < 1.0, np.clip(length, 0.0, None), 0.0)
        out[ys, xs] = acc * (complex(self.dn) / supersample**2)
        return out


@dataclass(frozen=True)
class Box(_Primitive):
    """Axis-aligned box with constant complex Δn (exact partial-volume voxelisation).

    Attributes
    ----------
    center_um : (float, float, float)
        Centre (x, y, z), µm.
    size_um : (float, float, float)
        Side lengths (x, y, z), µm.
    dn : complex
        Δn against the medium; imaginary part: absorption index κ.
    """

    center_um: tuple[float, float, float]
    size_um: tuple[float, float, float]
    dn: complex

    def _inside(self, z, y, x):
        inside = np.ones(z.shape, dtype=bool)
        for v, c, s in zip((x, y, z), self.center_um, self.size_um):
            inside &= np.abs(v - c) <= s / 2
        return inside

    def _half_depth(self):
        return self.size_um[2] / 2

    def _half_widths(self):
        return self.size_um[0] / 2, self.size_um[1] / 2

    def slab(self, z0, z1, y, x, pixel_um, supersample=4):
        """Pixel-averaged ∫Δn dz over [z0, z1].

        Parameters
        ----------
        z0, z1 : float
            Slab bounds, µm.
        y, x : ndarray, 1D
            Pixel centres, µm.
        pixel_um : float
            Pixel side, µm.
        supersample : int
            Unused: the box's pixel fractions are exact.

        Returns
        -------
        ndarray, complex128, (len(y), len(x))
            ∫ Δn dz per pixel, µm.
        """
        zlo, zhi = self.z_range()
        length = max(0.0, min(z1, zhi) - max(z0, zlo))
        fx = _interval_fraction(np.asarray(x, float), pixel_um, self.center_um[0], self.size_um[0])
        fy = _interval_fraction(np.asarray(y, float), pixel_um, self.center_um[1], self.size_um[1])
        return (length * complex(self.dn)) * np.outer(fy, fx)


def _interval_fraction(c, pixel, center, size):
    """Fraction of the pixels [c - p/2, c + p/2] covered by [center - size/2, center + size/2]."""
    lo = np.maximum(c - pixel / 2, center - size / 2)
    hi = np.minimum(c + pixel / 2, center + size / 2)
    return np.clip(hi - lo, 0.0, None) / pixel


def _window(y, x, box, pixel):
    """Index slices of the 1D coordinates that can touch the lateral box."""
    x0, x1, y0, y1 = box
    x, y = np.asarray(x), np.asarray(y)
    xs = slice(int(np.searchsorted(x, x0 - pixel)), int(np.searchsorted(x, x1 + pixel, side="right")))
    ys = slice(int(np.searchsorted(y, y0 - pixel)), int(np.searchsorted(y, y1 + pixel, side="right")))
    return ys, xs
