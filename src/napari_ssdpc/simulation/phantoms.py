"""Analytic refractive-index phantoms for the simulator and the tests.

Every phantom is a frozen dataclass with an analytic ground truth
``delta_n(z, y, x)`` (complex: the real part is n - n_medium, the imaginary part is
the absorption index κ, so a field of vacuum wavelength λ is damped as
``exp(-2π κ t / λ)`` over a length t), its extent (``z_range``, ``xy_box``), and two
partial-volume (anti-aliased) voxelisers used by the simulator and by tests:

- ``slab(z0, z1, y, x, pixel_um)``: ∫ Δn dz over [z0, z1] (µm), averaged over square
  pixels of side ``pixel_um`` centred on the 1D coordinates ``y``, ``x``;
- ``volume(z, y, x)``: the voxel average of Δn on a regular (z, y, x) grid.

Positions are (x, y, z) in µm; z > 0 is farther from the objective (docs/conventions.md).

The medium: ``medium_index=None`` means "the medium of the optics" (the simulator
fills it in and returns the bound phantom as ``Simulation.phantom``). A phantom with a
``medium_index`` (for example ``cell()`` in water, 1.33) makes ``simulate`` use
``optics.replace(medium_index=phantom.medium_index)``.

Samples that move or change from frame to frame (one phantom per frame) are in :mod:`.moving`.

The base class with the voxelisers and the free-form ``Composite`` are in :mod:`.phantom_base`;
this module holds the samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.phantom_base import Phantom
from napari_ssdpc.simulation.primitives import Box, Ellipsoid

__all__ = [
    "BarTarget",
    "Cell",
    "Sphere",
    "Spheres",
    "bar_target",
    "cell",
    "optics_for",
    "pmma_bead",
    "two_beads",
    "weak_bead",
]


@dataclass(frozen=True)
class Sphere(Phantom):
    """Homogeneous sphere of (complex) index ``n``; default = the paper's 13 µm PMMA bead.

    Attributes
    ----------
    center_um : (float, float, float)
        Centre (x, y, z), µm.
    diameter_um : float
        µm.
    n : complex
        Refractive index; imaginary part: absorption index κ.
    medium_index : float or None
        The medium, or None: the optics'.
    """

    center_um: tuple[float, float, float] = (0.0, 0.0, 0.0)
    diameter_um: float = 13.0
    n: complex = 1.49
    medium_index: float | None = None

    def __post_init__(self):
        if not self.diameter_um > 0:
            raise SsdpcError(f"Sphere diameter_um must be > 0, got {self.diameter_um}")

    def parts(self, medium_index):
        """The primitives (see :meth:`Phantom.parts`).

        Parameters
        ----------
        medium_index : float
            Index of the medium.

        Returns
        -------
        list of Ellipsoid
            One ellipsoid with Δn = n - ``medium_index``.
        """
        r = self.diameter_um / 2
        return [Ellipsoid(tuple(map(float, self.center_um)), (r, r, r), complex(self.n) - medium_index)]


@dataclass(frozen=True)
class Spheres(Phantom):
    """Several non-overlapping spheres in one medium (the spheres' own medium is ignored).

    Attributes
    ----------
    spheres : tuple of Sphere
    medium_index : float or None
        The medium, or None: the optics'.
    """

    spheres: tuple = ()
    medium_index: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "spheres", tuple(self.spheres))
        if not self.spheres:
            raise SsdpcError("Spheres needs at least one Sphere")

    def parts(self, medium_index):
        """The primitives (see :meth:`Phantom.parts`).

        Parameters
        ----------
        medium_index : float
            Index of the medium.

        Returns
        -------
        list of Ellipsoid
            One per sphere.
        """
        return [p for s in self.spheres for p in s.parts(medium_index)]


@dataclass(frozen=True)
class Cell(Phantom):
    """Ellipsoidal cell (index ``n``) with an ellipsoidal nucleus or inclusion (``n_nucleus``).

    The nucleus offset is given in the cell's own (rotated) frame; it must lie inside
    the cell (the two Δn add up: cytoplasm n - n_medium, nucleus n_nucleus - n).

    Attributes
    ----------
    center_um : (float, float, float)
        Centre of the cell (x, y, z), µm.
    semi_axes_um : (float, float, float)
        Semi-axes of the cell along x', y', z, µm.
    n : complex
        Index of the cytoplasm.
    nucleus_offset_um : (float, float, float)
        Nucleus centre relative to the cell centre, in the cell's rotated frame, µm.
    nucleus_semi_axes_um : (float, float, float)
        Semi-axes of the nucleus along x', y', z, µm.
    n_nucleus : complex
        Index of the nucleus.
    angle_deg : float
        Rotation of cell and nucleus about z, degrees.
    medium_index : float or None
        The medium (default water, 1.33), or None: the optics'.
    """

    center_um: tuple[float, float, float] = (0.0, 0.0, 0.0)
    semi_axes_um: tuple[float, float, float] = (12.0, 8.0, 5.0)
    n: complex = 1.37
    nucleus_offset_um: tuple[float, float, float] = (2.0, 0.5, 0.0)
    nucleus_semi_axes_um: tuple[float, float, float] = (4.5, 4.0, 3.0)
    n_nucleus: complex = 1.39
    angle_deg: float = 0.0
    medium_index: float | None = 1.33

    def parts(self, medium_index):
        """The primitives (see :meth:`Phantom.parts`).

        Parameters
        ----------
        medium_index : float
            Index of the medium.

        Returns
        -------
        list of Ellipsoid
            [cell, nucleus]; the nucleus's Δn is n_nucleus - n.
        """
        t = math.radians(self.angle_deg)
        ox, oy, oz = self.nucleus_offset_um
        cx, cy, cz = self.center_um
        nc = (cx + ox * math.cos(t) - oy * math.sin(t), cy + ox * math.sin(t) + oy * math.cos(t), cz + oz)
        return [
            Ellipsoid(
                tuple(map(float, self.center_um)),
                tuple(self.semi_axes_um),
                complex(self.n) - medium_index,
                self.angle_deg,
            ),
            Ellipsoid(nc, tuple(self.nucleus_semi_axes_um), complex(self.n_nucleus) - complex(self.n), self.angle_deg),
        ]


@dataclass(frozen=True)
class BarTarget(Phantom):
    """Thin absorbing USAF-like target at depth ``z_um``.

    One element per period: three vertical bars (varying along x) above three
    horizontal bars (varying along y), line width = period / 2, bar length = 5 line
    widths; elements sit side by side along x, centred on ``center_um`` (x, y).
    The bars transmit ``transmittance`` of the intensity (Δn = i κ with
    κ = -ln(T) λ / (4π t), for λ = ``wavelength_um``) and add ``phase_rad`` of phase.

    Attributes
    ----------
    period_um : tuple of float
        Bar period of each element, µm.
    z_um : float
        Depth of the target, µm.
    thickness_um : float
        Thickness t of the bars, µm.
    transmittance : float
        Intensity transmittance T of the bars, in (0, 1].
    phase_rad : float
        Phase the bars add, rad.
    wavelength_um : float
        Vacuum wavelength used to turn T and the phase into Δn, µm.
    center_um : (float, float)
        Centre of the target (x, y), µm.
    medium_index : float or None
        The medium, or None: the optics'.
    """

    period_um: tuple = (8.76, 6.2, 4.92, 4.38)
    z_um: float = 40.0
    thickness_um: float = 0.5
    transmittance: float = 0.1
    phase_rad: float = 0.0
    wavelength_um: float = 0.52
    center_um: tuple[float, float] = (0.0, 0.0)
    medium_index: float | None = None
    needs_medium = False

    def __post_init__(self):
        p = self.period_um
        object.__setattr__(self, "period_um", tuple(float(v) for v in (p if np.ndim(p) else (p,))))
        if not 0 < self.transmittance <= 1:
            raise SsdpcError(f"BarTarget transmittance must be in (0, 1], got {self.transmittance}")

    def parts(self, medium_index):
        """The primitives (see :meth:`Phantom.parts`).

        Parameters
        ----------
        medium_index : float
            Unused: the bars' Δn does not depend on the medium.

        Returns
        -------
        list of Box
            Six per element, alternately a vertical and a horizontal bar.
        """
        t, lam = self.thickness_um, self.wavelength_um
        dn = self.phase_rad * lam / (2 * math.pi * t) + 1j * (-math.log(self.transmittance) * lam / (4 * math.pi * t))
        widths = [p * 2.5 for p in self.period_um]  # element width = 5 line widths
        gap = max(self.period_um)
        total = sum(widths) + gap * (len(widths) - 1)
        x = self.center_um[0] - total / 2
        out = []
        for p, wdt in zip(self.period_um, widths):
            lw, length = p / 2, 2.5 * p
            xc = x + wdt / 2
            for i in (-1, 0, 1):
                out.append(Box((xc + i * p, self.center_um[1] - length / 2 - gap / 4, self.z_um), (lw, length, t), dn))
                out.append(Box((xc, self.center_um[1] + length / 2 + gap / 4 + i * p, self.z_um), (length, lw, t), dn))
            x += wdt + gap
        return out


# ---------------------------------------------------------------------------- factories
#: Index of the immersion oil the beads sit in (§3.2).
_OIL_INDEX = 1.518


def pmma_bead(center_um=(0.0, 0.0, 0.0)) -> Sphere:
    """The paper's bead: 13 µm PMMA (n 1.49) in oil of index 1.518 (§3.2).

    Parameters
    ----------
    center_um : (float, float, float)
        (x, y, z) of the centre, µm.

    Returns
    -------
    Sphere
    """
    return Sphere(tuple(center_um), 13.0, 1.49, medium_index=_OIL_INDEX)


def weak_bead(center_um=(0.0, 0.0, 10.0)) -> Sphere:
    """A weak bead: 6 µm, n 1.525 in oil 1.518 (Δn +0.007, 0.51 rad through its centre at 520 nm).

    Parameters
    ----------
    center_um : (float, float, float)
        (x, y, z) of the centre, µm.

    Returns
    -------
    Sphere
    """
    return Sphere(tuple(center_um), 6.0, 1.525, medium_index=_OIL_INDEX)


def two_beads() -> Spheres:
    """Two 6 µm beads (n 1.56) in 1.518, at z = -25 µm and z = +30 µm, 40 µm apart in x.

    Returns
    -------
    Spheres
    """
    beads = (Sphere((-20.0, 0.0, -25.0), 6.0, 1.56), Sphere((20.0, 0.0, 30.0), 6.0, 1.56))
    return Spheres(beads, medium_index=_OIL_INDEX)


def cell(**kw) -> Cell:
    """A cell (n 1.37) with a nucleus (n 1.39) in water (1.33); keywords override ``Cell`` fields.

    Parameters
    ----------
    **kw
        ``Cell`` fields.

    Returns
    -------
    Cell
    """
    return Cell(**kw)


def bar_target(period_um=(8.76, 6.2, 4.92, 4.38), z_um=40.0, **kw) -> BarTarget:
    """Thin absorbing USAF-like target; the paper resolves 4.38 µm periods (group 7 element 6).

    Parameters
    ----------
    period_um : tuple of float
        Bar periods, µm.
    z_um : float
        Depth of the target, µm.
    **kw
        More BarTarget fields.

    Returns
    -------
    BarTarget
    """
    return BarTarget(period_um=period_um, z_um=z_um, **kw)


def optics_for(phantom: Phantom | list | None, optics: Optics) -> Optics:
    """The optics with the phantom's own medium, when it declares one (the one place that rule lives).

    Parameters
    ----------
    phantom : Phantom, list of Phantom (a time series: the first decides) or None
        The sample.
    optics : Optics

    Returns
    -------
    Optics
        ``optics`` itself, or a copy with ``medium_index`` set to the phantom's.
    """
    first = phantom[0] if isinstance(phantom, list) else phantom
    if first is not None and first.medium_index is not None and first.medium_index != optics.medium_index:
        return optics.replace(medium_index=float(first.medium_index))
    return optics
