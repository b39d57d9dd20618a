"""The lenslet lattice fitted to measured EI centres: an affine lattice as the prior.

Real arrays are not perfect squares: the two lattice axes may differ in length and not
be quite orthogonal (a shear). The lattice here is affine, ``centre(n) = origin + M n``
with n = (col, row) and a general 2 x 2 ``M`` whose columns are the sensor steps of one
column and one row. Each lenslet keeps its own measured centre; the lattice labels the
lenslets, fills in those that could not be measured and gives the deviations.

The array's unit cell C (``settings.optics.lattice_cell``: square, or hex with rows offset by
half a pitch) is divided out before pitch, rotation, shear and aspect are read:
``M C⁻¹ = p R F`` for a perfect array, so a hex array shows no shear.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from napari_ssdpc.errors import SsdpcError

MIN_EIS = 3  # EIs needed to fix a lattice (two fix it, a third checks it)


@dataclass
class AffineLattice:
    """EI centre of lattice index n = (col, row): ``origin + M @ n`` (px)."""

    origin: np.ndarray
    M: np.ndarray
    flip: np.ndarray  # diag(±1, ±1) of the optics (the camera's mirroring)
    cell: np.ndarray = field(default_factory=lambda: np.eye(2))  # the unit cell C, in pitches

    def centres(self, n) -> np.ndarray:
        """EI centres of lattice indices.

        Parameters
        ----------
        n : array_like, (..., 2)
            Lattice indices (col, row).

        Returns
        -------
        ndarray, (..., 2)
            (x, y), px.
        """
        return self.origin + np.asarray(n, float) @ self.M.T

    def index(self, xy) -> np.ndarray:
        """Lattice indices of sensor positions (the inverse of :meth:`centres`).

        Parameters
        ----------
        xy : array_like, (..., 2)
            Sensor positions (x, y), px.

        Returns
        -------
        ndarray, (..., 2)
            Fractional lattice indices (col, row).
        """
        return np.linalg.solve(self.M, (np.asarray(xy, float) - self.origin).T).T

    @property
    def similar(self) -> np.ndarray:
        """M C⁻¹: the sensor image of a square unit step; p R F for a perfect array."""
        return self.M @ np.linalg.inv(self.cell)

    @property
    def axes_px(self) -> np.ndarray:
        """Lengths of the two steps (x, y of the array) of ``similar``, px."""
        return np.linalg.norm(self.similar, axis=0)

    @property
    def pitch(self) -> float:
        """Mean lattice step, px."""
        return float(self.axes_px.mean())

    @property
    def theta_deg(self) -> float:
        """Rotation of the nearest similarity (polar decomposition of M F), degrees."""
        u, _, vt = np.linalg.svd(self.similar @ self.flip)
        rot = u @ vt
        return math.degrees(math.atan2(rot[1, 0], rot[0, 0]))

    @property
    def shear_deg(self) -> float:
        """Angle between the array's x and y axes minus 90°, degrees (0 for a perfect square or hex)."""
        a, b = self.similar[:, 0], self.similar[:, 1]
        cos = abs(float(a @ b)) / float(np.linalg.norm(a) * np.linalg.norm(b))
        return 90.0 - math.degrees(math.acos(min(cos, 1.0)))

    @property
    def aspect(self) -> float:
        """Ratio of the two lattice steps minus 1."""
        ax = self.axes_px
        return float(ax[0] / ax[1] - 1)


MIN_AFFINE = 12  # with fewer EIs the lattice is a similarity (pitch, rotation): a square


def fit_affine(xy, n, flip, weights=None, cell=None, min_affine=MIN_AFFINE) -> tuple[AffineLattice, np.ndarray]:
    """Weighted least squares of centres xy (K, 2) on indices n (K, 2); returns the
    lattice and the residuals (K, 2) px.

    With ``min_affine`` (default ``MIN_AFFINE``) or more centres the lattice is affine (6 parameters); with fewer
    it is the array's ideal lattice (origin, pitch, rotation: x = ox + α n'x − β n'y,
    y = oy + β n'x + α n'y with n' = F C n), which extrapolates safely to the dark lenslets.

    Parameters
    ----------
    xy : ndarray, (K, 2)
        Centres (x, y), px.
    n : ndarray, (K, 2)
        Their indices (col, row).
    flip : ndarray, (2, 2)
        diag(±1, ±1) of the camera's mirroring.
    weights : ndarray, (K,), optional
        1/σ² of each centre.
    cell : ndarray, (2, 2), optional
        Unit cell in pitches (square by default).
    min_affine : int
        Fewest centres for the affine model.

    Returns
    -------
    lattice : AffineLattice
    residuals : ndarray, (K, 2)
        px.
    """
    xy, n = np.asarray(xy, float), np.asarray(n, float)
    cell = np.eye(2) if cell is None else np.asarray(cell, float)
    w = np.sqrt(np.ones(len(xy)) if weights is None else np.asarray(weights, float))
    if len(xy) >= min_affine:
        A = np.stack([np.ones(len(n)), n[:, 0], n[:, 1]], 1) * w[:, None]
        sol = np.linalg.lstsq(A, xy * w[:, None], rcond=None)[0]  # (3, 2)
        lat = AffineLattice(sol[0].copy(), sol[1:].T.copy(), flip, cell)
    else:
        nf = n @ (flip @ cell).T
        one, zero = np.ones(len(n)), np.zeros(len(n))
        A = np.concatenate(
            [np.stack([one, zero, nf[:, 0], -nf[:, 1]], 1), np.stack([zero, one, nf[:, 1], nf[:, 0]], 1)]
        )
        ww = np.concatenate([w, w])
        sol = np.linalg.lstsq(A * ww[:, None], np.concatenate([xy[:, 0], xy[:, 1]]) * ww, rcond=None)[0]
        M = np.array([[sol[2], -sol[3]], [sol[3], sol[2]]]) @ flip @ cell
        lat = AffineLattice(sol[:2].copy(), M, flip, cell)
    return lat, xy - lat.centres(n)


def _rot(theta_deg):
    t = math.radians(theta_deg)
    return np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])


def _basis(xy, pitch0, flip, cell):
    """The lattice matrix M (sensor steps of one column and one row) from the vectors
    between neighbouring EIs (those within 25 % of the optics' pitch ``pitch0``).

    A square array repeats every 90°, a hex array every 60°: the neighbour-vector angles,
    folded by that period, give the rotation θ within ±45° (square) or ±30° (hex). The
    ideal steps p R(θ) F C then pick, for each of the two steps, the neighbour vectors
    within a third of the period of it (either sign), whose median is the measured step:
    unequal axes and a shear come out as they are."""
    d = xy[None, :, :] - xy[:, None, :]
    dist = np.hypot(d[..., 0], d[..., 1])
    np.fill_diagonal(dist, np.inf)
    sel = np.abs(dist - pitch0) < 0.25 * pitch0  # the optics' pitch as the prior (±5 % is accepted)
    if not sel.any():
        raise SsdpcError("the elemental images do not form a lattice; check that the frame is a raw light-field frame")
    vec = d[sel]
    phi = np.arctan2(vec[:, 1], vec[:, 0])
    fold = 6 if abs(cell[0, 1]) > 1e-9 else 4  # hex: six neighbours
    theta = float(np.angle(np.mean(np.exp(1j * fold * phi)))) / fold
    ideal = pitch0 * _rot(math.degrees(theta)) @ flip @ cell
    M = ideal.copy()
    for j in range(2):
        cos = (vec @ ideal[:, j]) / (np.hypot(vec[:, 0], vec[:, 1]) * pitch0)
        near = np.abs(cos) > math.cos(2 * math.pi / fold / 3)
        if near.any():
            M[:, j] = np.median(vec[near] * np.sign(cos[near])[:, None], axis=0)
    return M


def assign(xy, strength, pitch0, flip, cell=None) -> tuple[AffineLattice, np.ndarray, np.ndarray]:
    """Lattice indices of the EI centres ``xy`` (K, 2).

    Indices are rounded from the neighbour-vector basis around the strongest EI, then the
    affine lattice is fitted and the indices rounded again from it until they settle, so
    a shear or unequal axes cannot shift an index far from the reference. The centres on
    the lattice must carry 70 % of the detection ``strength``. Returns the lattice, the
    indices (K', 2) and a mask (K,) of the centres on it.

    Parameters
    ----------
    xy : ndarray, (K, 2)
        Detected centres (x, y), px.
    strength : ndarray, (K,)
        Detection strength of each.
    pitch0 : float
        Expected pitch, px.
    flip : ndarray, (2, 2)
        diag(±1, ±1) of the camera's mirroring.
    cell : ndarray, (2, 2), optional
        Unit cell in pitches.

    Returns
    -------
    lattice : AffineLattice
    indices : ndarray, int, (K', 2)
    on_lattice : ndarray, bool, (K,)
    """
    xy = np.asarray(xy, float)
    if len(xy) < MIN_EIS:
        raise SsdpcError(
            f"only {len(xy)} elemental image(s) found, at least {MIN_EIS} are needed to fix the "
            "lattice; calibrate on a white frame taken with the condenser fully open"
        )
    cell = np.eye(2) if cell is None else np.asarray(cell, float)
    lat = AffineLattice(xy[int(np.argmax(strength))].copy(), _basis(xy, pitch0, flip, cell), flip, cell)
    on = np.ones(len(xy), bool)
    n = np.rint(lat.index(xy))
    for _ in range(4):
        n = np.rint(lat.index(xy))
        res = xy - lat.centres(n)
        on = np.hypot(res[:, 0], res[:, 1]) < 0.2 * lat.pitch
        if on.sum() < MIN_EIS:
            break
        new, _ = fit_affine(xy[on], n[on], flip, cell=cell)
        if np.allclose(new.M, lat.M, atol=1e-6 * lat.pitch) and np.allclose(new.origin, lat.origin, atol=1e-6):
            lat = new
            break
        lat = new
    if on.sum() < MIN_EIS or np.sum(strength[on]) < 0.7 * np.sum(strength):
        raise SsdpcError(
            f"only {on.sum()} of {len(xy)} elemental images lie on one lattice of pitch {lat.pitch:.1f} px "
            f"(optics: {pitch0:.1f} px); check mla.pitch_um and sensor.pixel_um, and that the frame "
            "is a raw light-field frame of this instrument"
        )
    return lat, n[on], on
