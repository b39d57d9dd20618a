"""Imaging side of the forward simulator: objective, lenslets, sensor.

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
   lenslet).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from napari_ssdpc.backend import cpu
from napari_ssdpc.physics.apertures import disk_fraction, subaperture_windows
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.physics.pupil import Pupil, eta
from napari_ssdpc.physics.waves import defocus_factor
from napari_ssdpc.simulation.camera import Camera
from napari_ssdpc.simulation.multislice import even_fast


def crop_size(optics, sampling):
    """Crop width (lattice units) that holds the sub-aperture and its 2ρ-wide intensity spectrum.

    Parameters
    ----------
    optics : Optics
    sampling : Sampling

    Returns
    -------
    int
        Even crop width, lattice units, at most ``sampling.n``.
    """
    nc = even_fast(int(math.ceil(4 * Pupil.of(optics).rho_max / sampling.du)) + 4)  # the widest sub-aperture
    return min(nc, sampling.n)


class Imager:
    """Accumulates the EI intensities of all lenslets over the source points.

    Parameters
    ----------
    optics : Optics
    sampling : Sampling
        The periodic object grid (n x n samples of ``dx_um`` µm).
    lenslets : list of Lenslet
        The K lenslets imaged (as built).

    Attributes
    ----------
    nc : int
        Crop width of the lenslet windows, lattice units.
    acc : ndarray, float64, (K, nc, nc)
        Accumulated EI intensities on the crop grid (object frame, period ``sampling.size_um``),
        intensity unit.
    """

    def __init__(self, optics, sampling, lenslets):
        self.optics, self.sampling, self.lenslets = optics, sampling, lenslets
        self.nc = crop_size(optics, sampling)
        # A_k = P_obj · P_k on each lenslet's crop (|amplitude|² = area fraction of the cell)
        pupil = Pupil.of(optics)
        self.centres, self.apert = subaperture_windows(lenslets, pupil, sampling.du, self.nc)
        self.off = np.arange(self.nc) - self.nc // 2
        self.acc = np.zeros((len(lenslets), self.nc, self.nc), dtype=np.float64)
        n = sampling.n
        x = sampling.x()
        self.mask = disk_fraction(x[None, :], x[:, None], optics.field_radius_um, sampling.dx_um).astype(np.float32)
        self.mask_spec = cpu().fft2(self.mask.astype(np.complex64))
        u = sampling.u()
        u2 = u[None, :] ** 2 + u[:, None] ** 2
        # objective pupil before the iris, absolute lattice in FFT order: every cell that touches the
        # pupil passes; the exact (anti-aliased) pupil edge is applied with A_k after the iris
        self.pupil = pupil.objective_cells(u2, sampling.du)
        if pupil.zernike:  # the objective's aberration, at the pupil (before the iris)
            ux, uy = np.broadcast_arrays(u[None, :], u[:, None])
            self.pupil = self.pupil * np.exp(1j * pupil.phase(ux, uy)).astype(np.complex64)
        self.eta = eta(u2, optics.medium_index, optics.wavelength_um)
        self.scale = (self.nc / n) ** 4 / (math.pi * optics.subaperture_radius**2)

    def image_spectrum(self, v_full, idx, z_exit):
        """Spectrum (V frame) of the field after the objective pupil and the iris.

        Parameters
        ----------
        v_full : ndarray, complex, (n, n)
            Exit envelope V on the full grid (FFT order).
        idx : ndarray, int, (2,)
            Lattice index (ix, iy) of the plane wave, units of du.
        z_exit : float
            Depth of the exit plane, µm.

        Returns
        -------
        ndarray, complex, (n, n)
            Spectrum in FFT order; index i holds the frequency u_i + w of the plane wave w.
        """
        n = self.sampling.n
        if getattr(self, "_z", None) != z_exit:  # exp(i2π z η(u)) P_obj(u) on the absolute lattice (Eq. 6)
            self._z = z_exit
            self._prop = (defocus_factor(self.eta, z_exit) * self.pupil).astype(np.complex64)
        F = cpu().fft2(v_full)
        e0 = self.eta[idx[1] % n, idx[0] % n].real
        F *= np.roll(self._prop, (-int(idx[1]), -int(idx[0])), axis=(0, 1))  # index i -> u_i + w
        F *= np.complex64(np.exp(-2j * np.pi * z_exit * e0))
        img = cpu().ifft2(F, overwrite_x=True)
        img *= self.mask
        return cpu().fft2(img, overwrite_x=True)

    def empty_spectrum(self, idx):
        """Spectrum after the iris of an unperturbed plane wave (no sample).

        Parameters
        ----------
        idx : ndarray, int, (2,)
            Lattice index (ix, iy) of the plane wave, units of du.

        Returns
        -------
        ndarray, complex, (n, n)
            The iris disk's spectrum (V frame, FFT order), 0 when the wave misses the pupil.
        """
        p = self.pupil[idx[1] % self.sampling.n, idx[0] % self.sampling.n]
        return self.mask_spec if p == 1 else self.mask_spec * p

    def add(self, spec, idx, weight):
        """Crop every lenslet's sub-aperture out of ``spec`` and add |field|² x weight.

        Parameters
        ----------
        spec : ndarray, complex, (n, n)
            Spectrum after the iris (V frame), from :meth:`image_spectrum` or :meth:`empty_spectrum`.
        idx : ndarray, int, (2,)
            Lattice index (ix, iy) of the plane wave, units of du.
        weight : float
            The source point's weight: the area of its cell inside the condenser disk, (cycles/µm)².
        """
        n = self.sampling.n
        rows = (self.centres[:, 1, None] - idx[1] + self.off[None, :]) % n
        cols = (self.centres[:, 0, None] - idx[0] + self.off[None, :]) % n
        crops = spec[rows[:, :, None], cols[:, None, :]] * self.apert
        f = cpu().ifft2(crops)
        self.acc += (weight * self.scale) * (f.real**2 + f.imag**2)

    def sum_sources(self, idx, weights, spectrum, progress=None):
        """Add every source point's spectrum (:meth:`add`) and return the :meth:`coefficients`.

        Parameters
        ----------
        idx : ndarray, int, (J, 2)
            Lattice indices (ix, iy) of the plane waves, units of du.
        weights : ndarray, (J,)
            The source points' weights, (cycles/µm)².
        spectrum : callable
            ``spectrum(j)``: the spectrum after the iris of source point j.
        progress : callable, optional
            ``progress(done, total)`` per source point.

        Returns
        -------
        ndarray, complex, (K, nc, nc)
            As :meth:`coefficients`.
        """
        for j in range(len(idx)):
            self.add(spectrum(j), idx[j], weights[j])
            if progress is not None:
                progress(j + 1, len(idx))
        return self.coefficients()

    def coefficients(self):
        """Fourier-series coefficients of each EI intensity (object frame, period = grid size).

        Returns
        -------
        ndarray, complex, (K, nc, nc)
            Coefficients at the frequencies ``fftfreq(nc, size_um / nc)`` cycles/µm, intensity unit.
        """
        return cpu().fft2(self.acc) / self.nc**2


# ------------------------------------------------------------------------------ render
def render(coeffs, centres, optics, sampling, grid, camera):
    """Place the band-limited EI intensities at their centres (K, 2) px on the sensor
    (float image, intensity unit).

    Parameters
    ----------
    coeffs : ndarray, complex, (K, m, m)
        Fourier-series coefficients of each EI's intensity at ``fftfreq(m, size_um / m)``
        cycles/µm (object frame, period ``sampling.size_um``).
    centres : ndarray, (K, 2)
        EI centres (x, y), px.
    optics : Optics
    sampling : Sampling
    grid : Grid
        Sensor-to-lattice geometry (pitch, rotation, flips).
    camera : Camera
        Its illumination fall-off is applied.

    Returns
    -------
    ndarray, float64, (H, W)
        Sensor image, intensity unit, clipped at 0.
    """
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
    # the fade stays outside the field stop's image: on small sensors (a 15 px pitch) a fixed
    # TAPER_PX would dim the EI's own rim and shrink the disk by 20 %
    taper = float(np.clip(0.5 * (half - optics.field_radius_um / s), 1.0, TAPER_PX))
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
            img *= _fade(Y - cy, half, taper)[:, None] * _fade(X - cx, half, taper)[None, :]
        else:
            img *= _fade(np.hypot(ox, oy) / s, half, taper)
        frame[Y[0] : Y[-1] + 1, X[0] : X[-1] + 1] += img
    return np.clip(frame, 0.0, None)


TAPER_PX = 8.0


def _fade(d, half, taper):
    """1 inside the patch, cosine fade to 0 over its outer ``taper`` pixels."""
    t = np.clip((half - np.abs(d)) / taper, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * t)


def _fourier_eval(c, f, y, x):
    """Real band-limited function sum_f c[fy, fx] exp(i2π(fx x + fy y)) on the grid y ⊗ x."""
    ex = np.exp(2j * np.pi * np.outer(x, f))
    ey = np.exp(2j * np.pi * np.outer(y, f))
    return (ey @ c @ ex.T).real


def array_as_built(optics, grid, camera, array=None):
    """Grid, camera, the lenslets as built (``array``: ArrayErrors) and their EI centres.

    Parameters
    ----------
    optics : Optics
    grid : Grid, optional
        Default the nominal grid.
    camera : Camera, optional
        Default ``Camera()``.
    array : ArrayErrors, optional
        Errors of the array; None: the ideal lattice.

    Returns
    -------
    grid : Grid
    camera : Camera
    lenslets : list of Lenslet
        The K lenslets as built.
    centres : ndarray, (K, 2)
        EI centres (x, y), px.
    """
    grid = grid or Grid.nominal(optics)
    camera = camera or Camera()
    lenslets = grid.lenslets(optics)
    if array is not None:
        lenslets, centres = array.apply(grid, lenslets, optics)
    else:
        centres = grid.lattice_px([ln.row for ln in lenslets], [ln.col for ln in lenslets]).reshape(-1, 2)
    return grid, camera, lenslets, centres
