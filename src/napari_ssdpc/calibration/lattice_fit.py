"""The lenslet lattice fitted to measured EI centres: an affine lattice as the prior.

Real arrays are not perfect squares: the two lattice axes may differ in length and not
be quite orthogonal (a shear). The lattice here is affine, ``centre(n) = origin + M n``
with n = (col, row) and a general 2 x 2 ``M`` whose columns are the sensor steps of one
column and one row. Each lenslet keeps its own measured centre; the lattice labels the
lenslets, fills in those that could not be measured and gives the deviations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from napari_ssdpc.errors import SsdpcError

MIN_EIS = 3  # EIs needed to fix a lattice (two fix it, a third checks it)


@dataclass
class AffineLattice:
    """EI centre of lattice index n = (col, row): ``origin + M @ n`` (px)."""

    origin: np.ndarray
    M: np.ndarray
    flip: np.ndarray  # diag(±1, ±1) of the optics (the camera's mirroring)

    def centres(self, n) -> np.ndarray:
        return self.origin + np.asarray(n, float) @ self.M.T

    def index(self, xy) -> np.ndarray:
        return np.linalg.solve(self.M, (np.asarray(xy, float) - self.origin).T).T

    @property
    def axes_px(self) -> np.ndarray:
        """Lengths of the two lattice steps (column, row), px."""
        return np.linalg.norm(self.M, axis=0)

    @property
    def pitch(self) -> float:
        """Mean lattice step, px."""
        return float(self.axes_px.mean())

    @property
    def theta_deg(self) -> float:
        """Rotation of the nearest similarity (polar decomposition of M F), degrees."""
        u, _, vt = np.linalg.svd(self.M @ self.flip)
        rot = u @ vt
        return math.degrees(math.atan2(rot[1, 0], rot[0, 0]))

    @property
    def shear_deg(self) -> float:
        """Angle between the two lattice axes minus 90°, degrees."""
        a, b = self.M[:, 0], self.M[:, 1]
        cos = abs(float(a @ b)) / float(np.linalg.norm(a) * np.linalg.norm(b))
        return 90.0 - math.degrees(math.acos(min(cos, 1.0)))

    @property
    def aspect(self) -> float:
        """Ratio of the two lattice steps minus 1."""
        ax = self.axes_px
        return float(ax[0] / ax[1] - 1)


MIN_AFFINE = 12  # with fewer EIs the lattice is a similarity (pitch, rotation): a square


def fit_affine(xy, n, flip, weights=None) -> tuple[AffineLattice, np.ndarray]:
    """Weighted least squares of centres xy (K, 2) on indices n (K, 2); returns the
    lattice and the residuals (K, 2) px.

    With ``MIN_AFFINE`` or more centres the lattice is affine (6 parameters); with fewer
    it is a square lattice (origin, pitch, rotation: x = ox + α n'x − β n'y,
    y = oy + β n'x + α n'y with n' = F n), which extrapolates safely to the dark lenslets."""
    xy, n = np.asarray(xy, float), np.asarray(n, float)
    w = np.sqrt(np.ones(len(xy)) if weights is None else np.asarray(weights, float))
    if len(xy) >= MIN_AFFINE:
        A = np.stack([np.ones(len(n)), n[:, 0], n[:, 1]], 1) * w[:, None]
        sol = np.linalg.lstsq(A, xy * w[:, None], rcond=None)[0]  # (3, 2)
        lat = AffineLattice(sol[0].copy(), sol[1:].T.copy(), flip)
    else:
        nf = n @ flip.T
        one, zero = np.ones(len(n)), np.zeros(len(n))
        A = np.concatenate(
            [np.stack([one, zero, nf[:, 0], -nf[:, 1]], 1), np.stack([zero, one, nf[:, 1], nf[:, 0]], 1)]
        )
        ww = np.concatenate([w, w])
        sol = np.linalg.lstsq(A * ww[:, None], np.concatenate([xy[:, 0], xy[:, 1]]) * ww, rcond=None)[0]
        M = np.array([[sol[2], -sol[3]], [sol[3], sol[2]]]) @ flip
        lat = AffineLattice(sol[:2].copy(), M, flip)
    return lat, xy - lat.centres(n)


def _rot(theta_deg):
    t = math.radians(theta_deg)
    return np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])


def _basis(xy, pitch0):
    """Two lattice step vectors (sensor px) from the vectors between neighbouring EIs
    (those within 25 % of the optics' pitch ``pitch0``).

    The angles of the neighbour vectors, folded modulo 90°, give the rotation θ in
    (−45°, 45°]; vectors near θ and θ + 90° (either sign) then give each axis separately,
    so unequal axes and a shear come out as they are."""
    d = xy[None, :, :] - xy[:, None, :]
    dist = np.hypot(d[..., 0], d[..., 1])
    np.fill_diagonal(dist, np.inf)
    sel = np.abs(dist - pitch0) < 0.25 * pitch0  # the optics' pitch as the prior (±5 % is accepted)
    if not sel.any():
        raise SsdpcError("the elemental images do not form a lattice; check that the frame is a raw light-field frame")
    vec = d[sel]
    phi = np.arctan2(vec[:, 1], vec[:, 0])
    theta = float(np.angle(np.mean(np.exp(4j * phi)))) / 4
    k = np.rint((phi - theta) / (math.pi / 2)).astype(int) % 4
    axes = []
    for along, against in ((0, 2), (1, 3)):
        v = np.concatenate([vec[k == along], -vec[k == against]])
        axes.append(np.median(v, axis=0) if len(v) else None)
    if axes[0] is None and axes[1] is None:
        raise SsdpcError("the elemental images do not form a lattice; check that the frame is a raw light-field frame")
    if axes[0] is None:
        axes[0] = _rot(-90) @ axes[1]
    if axes[1] is None:
        axes[1] = _rot(90) @ axes[0]
    return np.stack(axes, 1)


def assign(xy, strength, pitch0, flip) -> tuple[AffineLattice, np.ndarray, np.ndarray]:
    """Lattice indices of the EI centres ``xy`` (K, 2).

    Indices are rounded from the neighbour-vector basis around the strongest EI, then the
    affine lattice is fitted and the indices rounded again from it until they settle, so
    a shear or unequal axes cannot shift an index far from the reference. The centres on
    the lattice must carry 70 % of the detection ``strength``. Returns the lattice, the
    indices (K', 2) and a mask (K,) of the centres on it."""
    xy = np.asarray(xy, float)
    if len(xy) < MIN_EIS:
        raise SsdpcError(
            f"only {len(xy)} elemental image(s) found, at least {MIN_EIS} are needed to fix the "
            "lattice; calibrate on a white frame taken with the condenser fully open"
        )
    B = _basis(xy, pitch0)
    lat = AffineLattice(xy[int(np.argmax(strength))].copy(), B @ flip, flip)
    on = np.ones(len(xy), bool)
    n = np.rint(lat.index(xy))
    for _ in range(4):
        n = np.rint(lat.index(xy))
        res = xy - lat.centres(n)
        on = np.hypot(res[:, 0], res[:, 1]) < 0.2 * lat.pitch
        if on.sum() < MIN_EIS:
            break
        new, _ = fit_affine(xy[on], n[on], flip)
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
