"""Forward simulator of the Fourier light-field microscope: the project's ground truth.

It is deliberately more complete than the reconstruction model (no inverse crime):

1. Köhler illumination: the condenser disk is sampled as plane waves ON THE PERIODIC
   FREQUENCY LATTICE of the simulation grid (spacing du = 1 / grid size), every
   ``Source.step`` lattice units, each weighted by the exact area of its lattice cell
   inside the disk (so the total source area is right). Intensities of the source
   points add (Abbe's method; paper Eq. 2).
2. Multislice (beam propagation) through the 3D RI phantom: slabs of thickness
   ≤ ``dz_um`` (0.5 µm), a phase/absorption screen exp(i2π ∫Δn dz / λ) per slab,
   angular-spectrum propagation in the medium between them, exp(+i2π d η(u)),
   η(u) = sqrt((n/λ)² − |u|²). Empty slabs are skipped (one step across a gap). The
   field is carried as the envelope V = U·exp(−i2π w·x) of the tilted wave, on a
   sub-grid around the phantom, and embedded into the full grid afterwards.
3. The exit field is propagated forward by its signed depth z_exit to the focal plane
   z = 0, low-passed by the objective pupil, and cut by the iris, a field stop of radius
   ``optics.field_radius_um`` in the native image plane (object units).
4. Each lenslet k passes the sub-aperture A_k = P_obj · circ(|u − u_k| ≤ ρ)
   (u_k = −a/(λ f_obj m_r), docs/conventions.md). Its spectrum is cropped around u_k and
   inverse-transformed on a small grid (its intensity is band-limited to 2ρ), |.|² is
   summed over the source points.
5. The band-limited EI intensity is resampled exactly (Fourier series) onto the
   sensor pixels at M_EI through ``grid.matrix``, with sensor-pixel integration
   (a sinc in the Fourier domain) and the illumination fall-off, and placed at
   ``grid.lattice_px(row, col)`` (or where ``imperfect.ArrayErrors`` moved the
   lenslet). Then the camera model (``camera.Camera``).

Intensity unit: 1.0 = an EI whose sub-aperture lies wholly inside the source disk and
the objective pupil, with no sample, at the field centre.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft
from scipy import ndimage, special

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.physics.pupil import eta
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.camera import Camera
from napari_ssdpc.simulation.imperfect import ArrayErrors
from napari_ssdpc.simulation.phantoms import (
    BarTarget,
    Box,
    Cell,
    Composite,
    Ellipsoid,
    Phantom,
    Sphere,
    Spheres,
    bar_target,
    cell,
    moving_sample,
    optics_for,
    pmma_bead,
    two_beads,
)

__all__ = [
    "Camera",
    "Sampling",
    "Source",
    "Simulation",
    "simulate",
    "white_frame",
    "flat_frame",
    "white_intensity",
    "flat_intensity",
    "propagate",
    "exit_field",
    "effective_tan_theta",
    # phantoms (re-exported from core.phantoms)
    "Phantom",
    "Sphere",
    "Spheres",
    "Cell",
    "BarTarget",
    "Composite",
    "Ellipsoid",
    "Box",
    "pmma_bead",
    "two_beads",
    "cell",
    "bar_target",
    "moving_sample",
]

DX_UM = 0.3  # lateral sampling of the object grid (µm)
DZ_UM = 0.5  # maximal slab thickness of the multislice (µm)


# --------------------------------------------------------------------------- sampling
@dataclass(frozen=True)
class Sampling:
    """The periodic object-space grid: ``n`` x ``n`` samples of ``dx_um``.

    Its frequency lattice (spacing ``du = 1 / size_um``) carries the source points,
    the pupils and the lenslet sub-apertures."""

    n: int
    dx_um: float

    @classmethod
    def for_optics(cls, optics: Optics, dx_um: float = DX_UM, guard_um: float | None = None) -> Sampling:
        """Grid covering the field of view plus a guard band on each side
        (default max(15 µm, 15 % of the FOV)) for defocus blur and scattering."""
        guard = max(15.0, 0.15 * optics.fov_um) if guard_um is None else float(guard_um)
        if not 0 < dx_um <= 0.5 * optics.wavelength_um / (optics.na + optics.condenser_na):
            raise SsdpcError(
                f"dx_um {dx_um} is too coarse for NA {optics.na}: use <= "
                f"{0.5 * optics.wavelength_um / (optics.na + optics.condenser_na):.3f} µm"
            )
        n = _even_fast(math.ceil((optics.fov_um + 2 * guard) / dx_um))
        return cls(n, float(dx_um))

    @property
    def size_um(self) -> float:
        return self.n * self.dx_um

    @property
    def du(self) -> float:
        return 1.0 / self.size_um

    def x(self) -> np.ndarray:
        """Sample positions in FFT order (x = 0 at index 0)."""
        return np.fft.fftfreq(self.n, 1.0 / self.n) * self.dx_um

    def u(self) -> np.ndarray:
        return np.fft.fftfreq(self.n, self.dx_um)


def _even_fast(m: int) -> int:
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
    the disk area."""

    step: int = 2
    na: float | None = None
    supersample: int = 64

    def __post_init__(self):
        if int(self.step) < 1 or int(self.step) != self.step:
            raise SsdpcError(f"Source.step must be a positive integer (lattice units), got {self.step}")

    def radius(self, optics: Optics) -> float:
        na = optics.condenser_na if self.na is None else float(self.na)
        return na / optics.wavelength_um

    def points(self, optics: Optics, sampling: Sampling):
        """Integer lattice indices (K, 2) as (ix, iy), frequencies (K, 2) and weights (K,)."""
        r = self.radius(optics)
        h = int(self.step)
        du = sampling.du
        m = int(math.ceil(r / (h * du))) + 1
        i = np.arange(-m, m + 1)
        ix, iy = np.meshgrid(i, i)
        ix, iy = ix.ravel(), iy.ravel()
        cx, cy = ix * h * du, iy * h * du
        half = 0.5 * h * du
        near = np.hypot(np.abs(cx) - half, np.abs(cy) - half)  # nearest corner distance
        far = np.hypot(np.abs(cx) + half, np.abs(cy) + half)  # farthest corner
        wgt = np.where(far <= r, (h * du) ** 2, 0.0)
        edge = np.nonzero((far > r) & ((near < r) | (np.abs(cx) < half) | (np.abs(cy) < half)))[0]
        if len(edge):
            s = int(self.supersample)
            t = ((np.arange(s) + 0.5) / s - 0.5) * h * du
            sx = cx[edge, None, None] + t[None, None, :]
            sy = cy[edge, None, None] + t[None, :, None]
            wgt[edge] = np.mean(sx * sx + sy * sy <= r * r, axis=(1, 2)) * (h * du) ** 2
        keep = wgt > 0
        idx = np.stack([ix[keep] * h, iy[keep] * h], axis=1)
        return idx, idx * du, wgt[keep]


def _disk_fraction(x, y, radius, pixel, supersample=8):
    """Fraction of each pixel (side ``pixel``, centred at x, y) inside the disk r <= radius."""
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    r = np.hypot(x, y)
    out = (r <= radius).astype(np.float64)
    edge = np.abs(r - radius) < pixel
    if edge.any():
        t = ((np.arange(supersample) + 0.5) / supersample - 0.5) * pixel
        ex, ey = x[edge][:, None, None] + t[None, None, :], y[edge][:, None, None] + t[None, :, None]
        out[edge] = np.mean(ex * ex + ey * ey <= radius * radius, axis=(1, 2))
    return out


# ----------------------------------------------------------------------- propagation
def propagate(field, d_um: float, dx_um: float, wavelength_um: float, n_medium: float, tilt=(0.0, 0.0)):
    """Angular-spectrum propagation of a 2D field (y, x) over ``d_um`` forward
    (toward the objective) in a medium: spectrum x exp(+i2π d [η(u + w) − η(w)]);
    evanescent components (|u + w| > n/λ) are damped for either sign of d.

    ``tilt`` = w (cycles/µm): the field is the envelope V of U = V exp(i2π w·x); for
    w = 0 it is the field itself (the constant phase exp(i2π d η(0)) is dropped)."""
    field = np.asarray(field)
    ny, nx = field.shape
    H = _propagator(ny, nx, dx_um, d_um, wavelength_um, n_medium, tilt)
    out = sfft.ifft2(sfft.fft2(field, workers=-1) * H, workers=-1)
    return out.astype(field.dtype if np.iscomplexobj(field) else np.complex128, copy=False)


def _propagator(ny, nx, dx_um, d_um, wavelength_um, n_medium, tilt, dtype=np.complex64):
    uy = np.fft.fftfreq(ny, dx_um)[:, None] + tilt[1]
    ux = np.fft.fftfreq(nx, dx_um)[None, :] + tilt[0]
    e = eta(ux * ux + uy * uy, n_medium, wavelength_um)
    e0 = eta(tilt[0] ** 2 + tilt[1] ** 2, n_medium, wavelength_um).real
    # evanescent components decay in both directions (back-propagation must not amplify them)
    return (np.exp(2j * np.pi * d_um * (e.real - e0)) * np.exp(-2 * np.pi * abs(d_um) * e.imag)).astype(dtype)


class _Slabs:
    """Multislice: the phantom's phase/absorption screens on a sub-grid around it."""

    def __init__(self, phantom: Phantom, optics: Optics, sampling: Sampling, dz_um=DZ_UM, supersample=4):
        lam, nm, dx = optics.wavelength_um, optics.medium_index, sampling.dx_um
        z0, z1 = phantom.z_range()
        nz = max(1, int(math.ceil((z1 - z0) / dz_um - 1e-9)))
        dz = (z1 - z0) / nz
        x0, x1, y0, y1 = phantom.xy_box()
        margin = 10.0 + 0.3 * (z1 - z0)  # room for light scattered within the NA
        ns = _even_fast(math.ceil((max(x1 - x0, y1 - y0) + 2 * margin) / dx))
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
        """Envelope V of the exit field (at z_exit) for the plane wave of frequency ``tilt``."""
        v = self.screens[0].copy()
        cache = {}
        for k in range(1, len(self.screens)):
            d = round(self.z[k - 1] - self.z[k], 9)
            if d not in cache:
                cache[d] = _propagator(self.ns, self.ns, self.dx, d, self.lam, self.nm, tilt)
            v = sfft.ifft2(sfft.fft2(v, workers=-1) * cache[d], workers=-1) * self.screens[k]
        return v

    def embed(self, v, n) -> np.ndarray:
        """Full-grid envelope: 1 outside the sub-grid, tapered scattered part inside."""
        if self.full:
            return v
        out = np.ones((n, n), dtype=np.complex64)
        out[np.ix_(self.rows, self.cols)] = 1.0 + self.taper * (v - 1.0)
        return out


def exit_field(
    phantom: Phantom, optics: Optics, tilt=(0.0, 0.0), sampling: Sampling | None = None, dz_um: float = DZ_UM
):
    """Multislice exit field of one plane wave (envelope V, ``U = V exp(i2π w·x)``).

    Returns (V on the full grid in FFT order, z_exit µm, sampling). Useful for checks."""
    phantom = phantom.with_medium(optics.medium_index)
    optics = optics_for(phantom, optics)
    sampling = sampling or Sampling.for_optics(optics)
    slabs = _Slabs(phantom, optics, sampling, dz_um)
    v = slabs.embed(slabs.exit_envelope(np.asarray(tilt, float)), sampling.n)
    return v, slabs.z_exit, sampling


# ----------------------------------------------------------------------- lenslet optics
def _lenslet_windows(lenslets, optics, sampling, nc, supersample=8):
    """Per lenslet: absolute lattice index of the crop centre and the anti-aliased
    sub-aperture A_k = P_obj · P_k on the crop (|amplitude|² = area fraction of the cell)."""
    du, rho, cut = sampling.du, optics.subaperture_radius, optics.cutoff
    off = np.arange(nc) - nc // 2
    t = ((np.arange(supersample) + 0.5) / supersample - 0.5) * du
    centres, apert = [], []
    for ln in lenslets:
        c = np.rint(np.asarray(ln.u) / du).astype(int)
        ux = (c[0] + off) * du
        uy = (c[1] + off) * du
        sx = ux[None, :, None, None] + t[None, None, None, :]
        sy = uy[:, None, None, None] + t[None, None, :, None]
        inside = ((sx - ln.u[0]) ** 2 + (sy - ln.u[1]) ** 2 <= rho * rho) & (sx * sx + sy * sy <= cut * cut)
        centres.append(c)
        apert.append(np.sqrt(inside.mean(axis=(2, 3))))  # |A|² = area fraction: edge cells pass their share
    return np.array(centres), np.array(apert, dtype=np.float32)


def _crop_size(optics, sampling):
    """Crop width (lattice units) that holds the sub-aperture and its 2ρ-wide intensity spectrum."""
    nc = _even_fast(int(math.ceil(4 * optics.subaperture_radius / sampling.du)) + 4)
    return min(nc, sampling.n)


class _Imager:
    """Accumulates the EI intensities of all lenslets over the source points."""

    def __init__(self, optics, sampling, lenslets):
        self.optics, self.sampling, self.lenslets = optics, sampling, lenslets
        self.nc = _crop_size(optics, sampling)
        self.centres, self.apert = _lenslet_windows(lenslets, optics, sampling, self.nc)
        self.off = np.arange(self.nc) - self.nc // 2
        self.acc = np.zeros((len(lenslets), self.nc, self.nc), dtype=np.float64)
        n = sampling.n
        x = sampling.x()
        self.mask = _disk_fraction(x[None, :], x[:, None], optics.field_radius_um, sampling.dx_um).astype(np.float32)
        self.mask_spec = sfft.fft2(self.mask.astype(np.complex64), workers=-1)
        u = sampling.u()
        u2 = u[None, :] ** 2 + u[:, None] ** 2
        # objective pupil before the iris, absolute lattice in FFT order: every cell that touches the
        # pupil passes; the exact (anti-aliased) pupil edge is applied with A_k after the iris
        self.pupil = (u2 <= (optics.cutoff + sampling.du / math.sqrt(2)) ** 2).astype(np.float32)
        self.eta = eta(u2, optics.medium_index, optics.wavelength_um)
        self.scale = (self.nc / n) ** 4 / (math.pi * optics.subaperture_radius**2)

    def image_spectrum(self, v_full, idx, z_exit):
        """Spectrum (V frame) of the field after the objective pupil and the iris."""
        n = self.sampling.n
        if getattr(self, "_z", None) != z_exit:  # exp(i2π z η(u)) P_obj(u) on the absolute lattice
            self._z = z_exit
            self._prop = (np.exp(2j * np.pi * z_exit * self.eta.real) * self.pupil).astype(np.complex64)
        F = sfft.fft2(v_full, workers=-1)
        e0 = self.eta[idx[1] % n, idx[0] % n].real
        F *= np.roll(self._prop, (-int(idx[1]), -int(idx[0])), axis=(0, 1))  # index i -> u_i + w
        F *= np.complex64(np.exp(-2j * np.pi * z_exit * e0))
        img = sfft.ifft2(F, workers=-1, overwrite_x=True)
        img *= self.mask
        return sfft.fft2(img, workers=-1, overwrite_x=True)

    def empty_spectrum(self, idx):
        """Spectrum after the iris of an unperturbed plane wave (no sample)."""
        p = self.pupil[idx[1] % self.sampling.n, idx[0] % self.sampling.n]
        return self.mask_spec if p == 1 else self.mask_spec * p

    def add(self, spec, idx, weight):
        """Crop every lenslet's sub-aperture out of ``spec`` and add |field|² x weight."""
        n = self.sampling.n
        rows = (self.centres[:, 1, None] - idx[1] + self.off[None, :]) % n
        cols = (self.centres[:, 0, None] - idx[0] + self.off[None, :]) % n
        crops = spec[rows[:, :, None], cols[:, None, :]] * self.apert
        f = sfft.ifft2(crops, axes=(-2, -1), workers=-1)
        self.acc += (weight * self.scale) * (f.real**2 + f.imag**2)

    def coefficients(self):
        """Fourier-series coefficients of each EI intensity (object frame, period = grid size)."""
        return sfft.fft2(self.acc, axes=(-2, -1), workers=-1) / self.nc**2


# ------------------------------------------------------------------------------ render
def _render(coeffs, centres, optics, sampling, grid, camera):
    """Place the band-limited EI intensities at their centres (K, 2) px on the sensor
    (float image, intensity unit)."""
    H, W = optics.height_px, optics.width_px
    frame = np.zeros((H, W), dtype=np.float64)
    nc = coeffs.shape[-1]
    L = sampling.size_um
    f = np.fft.fftfreq(nc, L / nc)
    A = grid.matrix
    s = optics.pixel_um / optics.m_ei * optics.pitch_px / grid.pitch_px  # object µm per sensor px
    B = s * A.T  # sensor offset -> object
    # sensor-pixel integration: average over the pixel footprint B·[-1/2, 1/2]² (a sinc product)
    fx, fy = f[None, :], f[:, None]
    g0 = s * (A[0, 0] * fx + A[0, 1] * fy)
    g1 = s * (A[1, 0] * fx + A[1, 1] * fy)
    pix = np.sinc(g0) * np.sinc(g1)
    axis_aligned = abs(A[0, 1]) < 1e-12 and abs(A[1, 0]) < 1e-12
    # EI patch: as far as the periodic object grid allows (the diffraction tails of the
    # field stop reach well past the EI), faded out over its last TAPER_PX pixels. A rotated
    # patch is faded on the grid's inscribed circle (object radius L/2), so it holds the whole
    # field stop in every direction and nothing from the next period.
    half = (0.5 * L - 1.0) / s
    for (cx, cy), c in zip(centres, coeffs):
        X = np.arange(max(0, math.ceil(cx - half)), min(W, math.floor(cx + half) + 1))
        Y = np.arange(max(0, math.ceil(cy - half)), min(H, math.floor(cy + half) + 1))
        if len(X) == 0 or len(Y) == 0:
            continue
        cc = c * pix
        if axis_aligned:
            xo = B[0, 0] * (X - cx)
            yo = B[1, 1] * (Y - cy)
            img = _fourier_eval(cc, f, yo, xo)
            ox, oy = xo[None, :], yo[:, None]
        else:
            dX, dY = np.meshgrid(X - cx, Y - cy)
            ox = B[0, 0] * dX + B[0, 1] * dY
            oy = B[1, 0] * dX + B[1, 1] * dY
            step = s / 2
            gx = np.arange(ox.min() - 3 * step, ox.max() + 4 * step, step)
            gy = np.arange(oy.min() - 3 * step, oy.max() + 4 * step, step)
            fine = _fourier_eval(cc, f, gy, gx)
            img = ndimage.map_coordinates(fine, [(oy - gy[0]) / step, (ox - gx[0]) / step], order=3, mode="nearest")
        img = img * camera.illumination(np.hypot(ox, oy), optics.field_radius_um)
        if axis_aligned:
            img *= _fade(Y - cy, half)[:, None] * _fade(X - cx, half)[None, :]
        else:
            img *= _fade(np.hypot(ox, oy) / s, half)
        frame[Y[0] : Y[-1] + 1, X[0] : X[-1] + 1] += img
    return np.clip(frame, 0.0, None)


TAPER_PX = 8.0


def _fade(d, half):
    """1 inside the patch, cosine fade to 0 over the outer TAPER_PX pixels."""
    t = np.clip((half - np.abs(d)) / TAPER_PX, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * t)


def _fourier_eval(c, f, y, x):
    """Real band-limited function sum_f c[fy, fx] exp(i2π(fx x + fy y)) on the grid y ⊗ x."""
    ex = np.exp(2j * np.pi * np.outer(x, f))
    ey = np.exp(2j * np.pi * np.outer(y, f))
    return (ey @ c @ ex.T).real


# --------------------------------------------------------------------- sample-free frames
def _setup(optics, grid, camera, array=None):
    """Grid, camera, the lenslets as built (``array``: ArrayErrors) and their EI centres."""
    grid = grid or Grid.nominal(optics)
    camera = camera or Camera()
    lenslets = grid.lenslets(optics)
    if array is not None:
        lenslets, centres = array.apply(grid, lenslets, optics)
    else:
        centres = grid.lattice_px([ln.row for ln in lenslets], [ln.col for ln in lenslets]).reshape(-1, 2)
    return grid, camera, lenslets, centres


def white_intensity(
    optics: Optics, grid: Grid | None = None, camera: Camera | None = None, *, array: ArrayErrors | None = None
) -> np.ndarray:
    """Noise-free white frame (condenser fully open, σ = 1), intensity unit.

    Each EI is the iris disk, imaged through the lenslet's sub-aperture A_k in the
    incoherent limit (σ = 1), with brightness = the exact fraction of the sub-aperture
    inside the objective pupil (circle-overlap formula; no source quantisation). The
    brightness is set at the EI centre (the optical axis in the object): the lenslet
    PSF's tails spread ~1 % of the light past the field stop, which would otherwise
    lower the plateau by that much (see docs/simulator.md)."""
    grid, camera, lenslets, centres = _setup(optics, grid, camera, array)
    sampling = Sampling.for_optics(optics)
    nc = _crop_size(optics, sampling)
    f = np.fft.fftfreq(nc, sampling.size_um / nc)
    fr = np.hypot(f[None, :], f[:, None])
    R, L = optics.field_radius_um, sampling.size_um
    with np.errstate(invalid="ignore", divide="ignore"):
        disk = np.where(fr > 0, R * special.j1(2 * np.pi * R * fr) / fr, np.pi * R * R) / L**2
    coeffs = []
    for ln in lenslets:
        if ln.fraction <= 0:  # moved out of the pupil (imperfect.ArrayErrors): dark
            coeffs.append(np.zeros_like(disk))
            continue
        c = disk * _incoherent_otf(ln.u, optics, sampling.du, nc)
        coeffs.append(c * (ln.fraction / c.sum().real))  # value at the EI centre = exact fraction
    coeffs = np.array(coeffs)
    return _render(coeffs.astype(np.complex128), centres, optics, sampling, grid, camera)


def _incoherent_otf(u_k, optics, du, nc, q=4):
    """Normalised autocorrelation of A_k = P_obj · P_k at lags that are multiples of du."""
    rho, cut = optics.subaperture_radius, optics.cutoff
    d = du / q
    m = int(math.ceil((rho + 2 * du) / d))
    t = np.arange(-m, m + 1) * d
    sx, sy = u_k[0] + t[None, :], u_k[1] + t[:, None]
    a = (((sx - u_k[0]) ** 2 + (sy - u_k[1]) ** 2 <= rho * rho) & (sx * sx + sy * sy <= cut * cut)).astype(float)
    N = sfft.next_fast_len(2 * len(t) + 1)
    ac = sfft.ifft2(np.abs(sfft.fft2(a, s=(N, N), workers=-1)) ** 2, workers=-1).real
    lag = (np.fft.fftfreq(nc, 1.0 / nc).astype(int) * q) % N
    otf = ac[np.ix_(lag, lag)]
    return otf / ac[0, 0]


def white_frame(
    optics: Optics,
    grid: Grid | None = None,
    camera: Camera | None = None,
    rng=None,
    *,
    array: ArrayErrors | None = None,
) -> np.ndarray:
    """Raw uint16 white frame (σ = 1): every lenslet inside the pupil is lit, edge
    lenslets at the exact fraction of their sub-aperture inside the pupil."""
    camera = camera or Camera()
    return camera.apply(white_intensity(optics, grid, camera, array=array), camera.rng(rng))


def flat_intensity(
    optics: Optics,
    grid: Grid | None = None,
    camera: Camera | None = None,
    source: Source | None = None,
    progress=None,
    *,
    array: ArrayErrors | None = None,
) -> np.ndarray:
    """Noise-free flat frame at the optics' condenser NA, intensity unit.

    Same source sampling and the same imaging code as ``simulate``, so that
    ``simulate(...).intensity / flat_intensity(...)`` is exactly 1 where the sample
    does not scatter."""
    grid, camera, lenslets, centres = _setup(optics, grid, camera, array)
    sampling = Sampling.for_optics(optics)
    imager = _Imager(optics, sampling, lenslets)
    idx, _, wgt = (source or Source()).points(optics, sampling)
    for j in range(len(idx)):
        imager.add(imager.empty_spectrum(idx[j]), idx[j], wgt[j])
        if progress is not None:
            progress(j + 1, len(idx))
    return _render(imager.coefficients(), centres, optics, sampling, grid, camera)


def flat_frame(
    optics: Optics,
    grid: Grid | None = None,
    camera: Camera | None = None,
    rng=None,
    source: Source | None = None,
    *,
    array: ArrayErrors | None = None,
) -> np.ndarray:
    """Raw uint16 flat frame (no sample) at the sample's condenser NA (σ < 1)."""
    camera = camera or Camera()
    return camera.apply(flat_intensity(optics, grid, camera, source, array=array), camera.rng(rng))


# ----------------------------------------------------------------------------- simulate
@dataclass
class Simulation:
    """Result of ``simulate``: raw frame, noise-free intensity and what made them."""

    frame: np.ndarray
    intensity: np.ndarray
    grid: Grid
    lenslets: list
    phantom: Phantom | None
    optics: Optics
    source: Source
    sampling: Sampling
    camera: Camera
    seconds: float = 0.0
    n_source_points: int = 0
    info: dict = field(default_factory=dict)


def simulate(
    phantom: Phantom | None,
    optics: Optics,
    grid: Grid | None = None,
    camera: Camera | None = None,
    source: Source | None = None,
    rng=None,
    progress=None,
    *,
    dz_um: float = DZ_UM,
    array: ArrayErrors | None = None,
) -> Simulation:
    """Simulate one raw frame of ``phantom`` (None: no sample, the flat frame).

    ``progress(done, total)`` is called after every source point. A phantom with its
    own ``medium_index`` (e.g. ``cell()``, water) replaces the optics' medium; the
    optics used is returned as ``Simulation.optics``."""
    t0 = time.perf_counter()
    optics = optics_for(phantom, optics)
    if phantom is not None:
        phantom = phantom.with_medium(optics.medium_index)
    grid, camera, lenslets, centres = _setup(optics, grid, camera, array)
    source = source or Source()
    sampling = Sampling.for_optics(optics)
    imager = _Imager(optics, sampling, lenslets)
    idx, w, wgt = source.points(optics, sampling)
    slabs = _Slabs(phantom, optics, sampling, dz_um) if phantom is not None else None
    for j in range(len(idx)):
        if slabs is None:
            spec = imager.empty_spectrum(idx[j])
        else:
            v = slabs.embed(slabs.exit_envelope(w[j]), sampling.n)
            spec = imager.image_spectrum(v, idx[j], slabs.z_exit)
        imager.add(spec, idx[j], wgt[j])
        if progress is not None:
            progress(j + 1, len(idx))
    intensity = _render(imager.coefficients(), centres, optics, sampling, grid, camera)
    frame = camera.apply(intensity, camera.rng(rng))
    info = {
        "subgrid": slabs.ns if slabs else 0,
        "screens": len(slabs.screens) if slabs else 0,
        "grid_n": sampling.n,
        "crop": imager.nc,
    }
    return Simulation(
        frame,
        intensity,
        grid,
        lenslets,
        phantom,
        optics,
        source,
        sampling,
        camera,
        time.perf_counter() - t0,
        len(idx),
        info,
    )


# ------------------------------------------------------------------------------ helpers
def effective_tan_theta(optics: Optics, lenslet, supersample: int = 400) -> np.ndarray:
    """|pupil|²-weighted mean over A_k of tanθ(u)·û(u) (vector, object frame).

    A point at depth z appears displaced by z times this vector in the EI of
    ``lenslet`` (docs/conventions.md); it is about 6 % below the centre value for clipped EIs."""
    rho, cut = optics.subaperture_radius, optics.cutoff
    t = np.linspace(-rho, rho, supersample)
    ux, uy = np.meshgrid(lenslet.u[0] + t, lenslet.u[1] + t)
    a = ((ux - lenslet.u[0]) ** 2 + (uy - lenslet.u[1]) ** 2 <= rho * rho) & (ux * ux + uy * uy <= cut * cut)
    s2 = (optics.wavelength_um / optics.medium_index) ** 2 * (ux * ux + uy * uy)
    k = optics.wavelength_um / optics.medium_index / np.sqrt(1 - s2)  # tanθ·û = k·u
    return np.array([np.mean((k * ux)[a]), np.mean((k * uy)[a])])
