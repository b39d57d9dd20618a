"""Reference wave-optics PSF of the Fourier light-field microscope: paper Eq. 6 on the sensor.

Physics (docs/conventions.md, paper Eq. 6). A point at (0, 0, z) has, in the focal plane, the angular
spectrum exp(i2π z η(u)) with η(u) = sqrt((n/λ)² − |u|²) (forward propagation by +z). The
objective passes |u| ≤ NA/λ, and the relay puts frequency u at x_mla = −λ f_obj m_r u on the MLA
(the M_relay scaling of Eq. 6, inverted). Lenslet k multiplies by the transmittance
T = circ(|x − c_k| ≤ r_ml) exp(−iπ|x − c_k|²/(λ f_ml)); the field then propagates over f_ml to the
sensor (angular spectrum), and the camera integrates |U|² over each pixel.

It is slow and exact to the sampling; :class:`napari_ssdpc.physics.psf.LensletPSF` is the fast
per-lenslet form the reconstruction uses, tested against it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import cpu
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.physics.pupil import Pupil, axial_frequency, soft_disk
from napari_ssdpc.physics.waves import transfer_function
from napari_ssdpc.settings.lenslets import Lenslet
from napari_ssdpc.settings.optics import Optics

__all__ = ["ReferencePSF", "reference_psf"]


@dataclass
class ReferencePSF:
    """Sensor images of a point at each depth (Eq. 6), on a region of the sensor.

    ``images[i, r, c]`` is the energy in sensor pixel (x, y) = origin_px + (c, r) for depth
    ``z_um[i]``, as a fraction of the light through one unclipped lenslet.
    """

    images: np.ndarray
    z_um: np.ndarray
    origin_px: tuple[float, float]
    axis_px: tuple[float, float]
    lenslets: list[Lenslet]
    pixel_um: float

    @property
    def centres_px(self) -> np.ndarray:
        """EI centres (x, y) in sensor px: directly behind each lenslet centre."""
        a = np.array([ln.a_um for ln in self.lenslets], dtype=float)
        return np.asarray(self.axis_px) + a / self.pixel_um

    def windows(self, shape):
        """EI windows (Z, K, h, w) around the pixel nearest each EI centre, and the sub-pixel
        offsets (K, 2) (x, y) of the window centre from the EI centre, in px (for LensletPSF).

        Parameters
        ----------
        shape : (int, int)
            Window size (h, w), px.

        Returns
        -------
        windows : ndarray, (Z, K, h, w)
            The reference PSF images cut around each EI.
        offsets : ndarray, int, (K, 2)
            (x, y) of each window centre minus its EI centre, px.
        """
        h, w = shape
        c = self.centres_px - np.asarray(self.origin_px)
        ic = np.rint(c).astype(int)
        out = np.empty((len(self.z_um), len(self.lenslets), h, w), self.images.dtype)
        for k, (cx, cy) in enumerate(ic):
            y0, x0 = cy - h // 2, cx - w // 2
            if y0 < 0 or x0 < 0 or y0 + h > self.images.shape[1] or x0 + w > self.images.shape[2]:
                raise SsdpcError("EI window leaves the reference region; compute it with a larger margin_um")
            out[:, k] = self.images[:, y0 : y0 + h, x0 : x0 + w]
        return out, ic - c


def reference_psf(
    optics: Optics,
    grid_or_lenslets=None,
    z_um=0.0,
    *,
    oversample: int = 1,
    margin_um: float | None = None,
    pixel_integration: bool = True,
    progress=None,
) -> ReferencePSF:
    """PSF of the whole instrument by paper Eq. 6, for every depth in ``z_um``.

    Parameters
    ----------
    optics : Optics
    grid_or_lenslets : Grid, list of Lenslet or None
        A ``Grid`` (axis position on the sensor; unrotated and unmirrored), a list of ``Lenslet``
        (axis on a pixel centre of the region), or None (nominal lattice).
    z_um : float or sequence of float
        Depths of the point, µm.
    oversample : int
        Odd; samples each pixel q×q times. The pixel integration is an exact box filter in the
        Fourier domain (sinc), so q = 1 already converges for the paper's optics.
    margin_um : float, optional
        Region beyond the objective pupil on the MLA, µm (default half a pitch).
    pixel_integration : bool
        Integrate over each camera pixel.
    progress : callable, optional
        ``progress(done, total)`` after each depth.

    Returns
    -------
    ReferencePSF
        Sensor images (Z, rows, cols), energy per pixel as a fraction of one unclipped lenslet's light.
    """
    q = int(oversample)
    if q < 1 or q % 2 == 0:
        raise SsdpcError(f"oversample must be an odd integer >= 1, got {oversample}")
    z = np.atleast_1d(np.asarray(z_um, dtype=float))
    pix = optics.pixel_um
    margin = 0.5 * optics.pitch_um if margin_um is None else float(margin_um)
    half_px = int(math.ceil((optics.pupil_radius_mla_um + margin) / pix))
    if isinstance(grid_or_lenslets, Grid):
        grid = grid_or_lenslets
        if not np.allclose(grid.matrix, np.eye(2)):
            raise SsdpcError("reference_psf needs an unrotated, unmirrored grid; use Grid.nominal(optics)")
        axis = np.asarray(grid.axis_px, dtype=float)
        offset = grid.axis_offset_um(optics)
        apertures = nominal_lenslets(optics, offset, min_fraction=1e-9)
        lenslets = grid.lenslets(optics)
        origin = np.rint(axis) - half_px
    else:
        lenslets = nominal_lenslets(optics) if grid_or_lenslets is None else list(grid_or_lenslets)
        apertures = lenslets
        origin = np.array([0.0, 0.0])
        axis = origin + half_px
    npx = 2 * half_px + 1
    n = sfft.next_fast_len(npx * q)
    dx = pix / q
    # fine sample j sits at sensor px origin + (j - q//2)/q; pixel m centre at j = m q + q//2
    xs = ((origin[0] + (np.arange(n) - q // 2) / q) - axis[0]) * pix  # MLA x (µm) from the axis
    ys = ((origin[1] + (np.arange(n) - q // 2) / q) - axis[1]) * pix
    field0, eta = _pupil_field_on_mla(optics, xs, ys, dx)
    field0 = field0 * _mla_transmittance(optics, apertures, xs, ys, dx)
    prop = _angular_spectrum(optics, n, dx)
    fx = sfft.fftfreq(n, dx)
    box = np.sinc(fx * pix)
    scale = pix * pix / (math.pi * optics.lenslet_radius_um**2)
    images = np.empty((len(z), npx, npx))
    for i, zi in enumerate(z):
        u = field0 * np.exp(2j * np.pi * zi * eta)
        u = cpu().ifft2(cpu().fft2(u) * prop)
        inten = np.abs(u) ** 2
        if pixel_integration:
            inten = cpu().irfft2(cpu().rfft2(inten) * box[:, None] * box[None, : n // 2 + 1], s=(n, n))
        images[i] = inten[q // 2 :: q, q // 2 :: q][:npx, :npx] * scale
        if progress is not None:
            progress(i + 1, len(z))
    return ReferencePSF(
        images, z, (float(origin[0]), float(origin[1])), (float(axis[0]), float(axis[1])), list(lenslets), pix
    )


def _pupil_field_on_mla(optics: Optics, xs, ys, dx):
    """Objective pupil imaged onto the MLA (x_mla = −λ f_obj m_r u) and η at each sample."""
    scale = optics.wavelength_um * optics.f_obj_um * optics.m_r
    ux, uy = -xs[None, :] / scale, -ys[:, None] / scale
    full = Pupil.of(optics)
    pupil = full.objective(ux, uy, step=dx / scale) * np.exp(1j * full.phase(ux, uy))  # the objective's aberration
    return pupil, axial_frequency(ux, uy, optics)


def _mla_transmittance(optics: Optics, apertures, xs, ys, dx):
    """T(x) = Σ_k circ(|x − c_k| ≤ r_ml) exp(−iπ|x − c_k|²/(λ f_ml)) (Eq. 6, ref. 70)."""
    r = optics.lenslet_radius_um
    lam_f = optics.wavelength_um * optics.mla_focal_length_mm * 1e3
    t = np.zeros((len(ys), len(xs)), complex)
    for ln in apertures:
        cx, cy = ln.a_um
        jx = np.nonzero(np.abs(xs - cx) <= r + dx)[0]
        jy = np.nonzero(np.abs(ys - cy) <= r + dx)[0]
        if len(jx) == 0 or len(jy) == 0:
            continue
        sx, sy = slice(jx[0], jx[-1] + 1), slice(jy[0], jy[-1] + 1)
        d2 = (xs[sx][None, :] - cx) ** 2 + (ys[sy][:, None] - cy) ** 2
        t[sy, sx] += soft_disk(np.sqrt(d2), r, dx) * np.exp(-1j * np.pi * d2 / lam_f)
    return t


def _angular_spectrum(optics: Optics, n, dx):
    """Propagator over f_ml in air, exp(i2π f_ml sqrt(1/λ² − |f|²)) without its constant phase."""
    lam = optics.wavelength_um
    f = sfft.fftfreq(n, dx)
    f2 = f[None, :] ** 2 + f[:, None] ** 2
    return transfer_function(f2, optics.mla_focal_length_mm * 1e3, 1.0, lam, eta0=1.0 / lam, cut_evanescent=True)
