"""Geometry of the lenslet lattice on the sensor, shared by the simulator and calibration.

Frames of reference
- MLA frame: x right, y down (the object axes of docs/conventions.md), in µm on the MLA.
- Sensor frame: x = column, y = row, in pixels, origin at the centre of pixel (0, 0).

A displacement ``d`` in the MLA frame (expressed in sensor pixels) lands on the sensor
as ``R(rotation) @ F @ d`` with ``F = diag(±1, ±1)`` from ``flip_x``/``flip_y``.
``rotation_deg`` is measured from the sensor +x axis toward +y (clockwise as displayed,
since rows run downwards). The same matrix maps the content of every elemental image:
an in-focus object point at (x, y) µm appears at ``centre + A @ (x, y) * M_EI / pixel``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.settings.lenslets import Lenslet, lattice_cell
from napari_ssdpc.settings.optics import Optics


@dataclass(frozen=True)
class Grid:
    """Lenslet lattice on the sensor: optical axis, reference vertex, pitch, rotation."""

    axis_px: tuple[float, float]  # optical axis on the sensor (x, y), sub-pixel
    vertex_px: tuple[float, float]  # reference lattice vertex nearest the axis (x, y)
    pitch_px: float
    rotation_deg: float = 0.0
    flip_x: bool = False
    flip_y: bool = False
    lattice: str = "square"  # the array's unit cell: "square" or "hex" (settings.optics.lattice_cell)

    @classmethod
    def nominal(cls, optics: Optics, axis_px=None, axis_offset_px=(0.0, 0.0), rotation_deg=0.0, pitch_px=None) -> Grid:
        """Grid of an ideal instrument. ``axis_offset_px`` is the optical axis position
        relative to the lattice vertex, in pixels along the lattice axes.

        Parameters
        ----------
        optics : Optics
            Pitch, sensor size and flips of the instrument.
        axis_px : (float, float), optional
            Optical axis on the sensor (x, y), px; default the sensor's centre.
        axis_offset_px : (float, float)
            Axis relative to the reference vertex along the lattice axes, px.
        rotation_deg : float
            MLA rotation on the sensor, degrees.
        pitch_px : float, optional
            Lenslet pitch on the sensor, px; default the optics'.

        Returns
        -------
        Grid
        """
        if axis_px is None:
            axis_px = ((optics.width_px - 1) / 2.0, (optics.height_px - 1) / 2.0)
        g = cls(
            xy_pair(axis_px),
            (0.0, 0.0),
            float(pitch_px or optics.pitch_px),
            float(rotation_deg),
            optics.flip_x,
            optics.flip_y,
            optics.grid,
        )
        off = g.matrix @ np.asarray(axis_offset_px, dtype=float)
        vertex = np.asarray(g.axis_px) - off
        return replace(g, vertex_px=(float(vertex[0]), float(vertex[1])))

    @property
    def matrix(self) -> np.ndarray:
        """2x2 map from the MLA/object frame to the sensor frame (rotation @ flip)."""
        t = math.radians(self.rotation_deg)
        rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
        flip = np.diag([-1.0 if self.flip_x else 1.0, -1.0 if self.flip_y else 1.0])
        return rot @ flip

    def lattice_px(self, row, col) -> np.ndarray:
        """Sensor position (x, y) of the lenslet centre(s) with lattice index (row, col).

        Parameters
        ----------
        row, col : int or array_like of int
            Lattice indices (broadcast together).

        Returns
        -------
        ndarray, float64, (..., 2)
            (x, y) in sensor pixels.
        """
        row, col = np.broadcast_arrays(np.asarray(row, float), np.asarray(col, float))
        d = np.stack([col + 0.5, row + 0.5], axis=-1) @ (self.pitch_px * lattice_cell(self.lattice)).T
        return np.asarray(self.vertex_px) + d @ self.matrix.T

    def axis_offset_px(self) -> np.ndarray:
        """Optical axis relative to the reference vertex, along the lattice axes (px)."""
        d = np.asarray(self.axis_px) - np.asarray(self.vertex_px)
        return np.linalg.solve(self.matrix, d)

    def axis_offset_um(self, optics: Optics) -> np.ndarray:
        """Same offset in µm on the MLA (uses the measured pitch as the length scale).

        Parameters
        ----------
        optics : Optics

        Returns
        -------
        ndarray, (2,)
            Offset along the lattice axes, µm on the MLA.
        """
        return self.axis_offset_px() * optics.pitch_um / self.pitch_px

    def lenslets(self, optics: Optics, min_fraction: float = 1e-3) -> list[Lenslet]:
        """Lenslets overlapping the pupil for this axis position.

        Parameters
        ----------
        optics : Optics
        min_fraction : float
            Smallest part of a lenslet inside the pupil to count it.

        Returns
        -------
        list of Lenslet
        """
        return nominal_lenslets(optics, self.axis_offset_um(optics), min_fraction=min_fraction)

    def object_to_sensor(self, lenslet: Lenslet, xy_um, optics: Optics) -> np.ndarray:
        """Sensor position of an in-focus object point (x, y) µm in the EI of ``lenslet``.

        Parameters
        ----------
        lenslet : Lenslet
        xy_um : array_like, (..., 2)
            Object position (x, y), µm from the optical axis.
        optics : Optics

        Returns
        -------
        ndarray, (..., 2)
            (x, y) on the sensor, px.
        """
        scale = optics.m_ei / optics.pixel_um * self.pitch_px / optics.pitch_px
        centre = self.lattice_px(lenslet.row, lenslet.col)
        return centre + (np.asarray(xy_um, dtype=float) * scale) @ self.matrix.T

    def to_dict(self) -> dict:
        """The grid as plain values (the calibration JSON).

        Returns
        -------
        dict
            JSON-ready: axis, vertex (px), pitch (px), rotation (degrees), flips and lattice.
        """
        return {
            "axis_px": list(self.axis_px),
            "vertex_px": list(self.vertex_px),
            "pitch_px": self.pitch_px,
            "rotation_deg": self.rotation_deg,
            "flip_x": self.flip_x,
            "flip_y": self.flip_y,
            "lattice": self.lattice,
        }

    @classmethod
    def from_dict(cls, d: dict) -> Grid:
        """The grid of a calibration JSON.

        Parameters
        ----------
        d : dict
            As written by :meth:`to_dict`.

        Returns
        -------
        Grid
        """
        return cls(
            xy_pair(d["axis_px"]),
            xy_pair(d["vertex_px"]),
            float(d["pitch_px"]),
            float(d.get("rotation_deg", 0.0)),
            bool(d.get("flip_x", False)),
            bool(d.get("flip_y", False)),
            str(d.get("lattice", "square")),
        )


def xy_pair(values) -> tuple[float, float]:
    """(x, y) as two floats.

    Parameters
    ----------
    values : sequence of two numbers

    Returns
    -------
    (float, float)
    """
    x, y = values
    return float(x), float(y)


def lenslet_case(optics: Optics, lenslet: Lenslet) -> str:
    """Where a lenslet's sub-aperture lies relative to the source disk: the one lenslet-regime rule.

    Parameters
    ----------
    optics : Optics
    lenslet : Lenslet

    Returns
    -------
    str
        'inside' (wholly inside the source disk: incoherent, no first-order phase contrast),
        'straddling' (DPC-like phase contrast) or 'outside' (dark field); docs/conventions.md.
    """
    from napari_ssdpc.physics.pupil import Pupil

    u_k, rho, _ = Pupil.of(optics).lenslet(lenslet)  # its own sub-aperture
    (cx, cy), rs = optics.source_centre, optics.source_radius
    d = math.hypot(u_k[0] - cx, u_k[1] - cy)
    if d + rho <= rs:
        return "inside"
    if d - rho >= rs:
        return "outside"
    return "straddling"
