"""Fast per-lenslet form of the wave-optics PSF of the Fourier light-field microscope (paper Eq. 6).

The full Eq. 6 (pupil on the MLA, lenslet transmittance, propagation to the sensor) is
:func:`napari_ssdpc.physics.psf_reference.reference_psf`, which this form is tested against.

Fast form. Lens phase + propagation over f_ml is a Fourier transform, so behind lenslet k, at
sensor offset s = M_EI·r from the lenslet centre, the EI is the coherent image of the point through
the sub-aperture P_k(u) = P_obj(u)·circ(|u − u_k| ≤ ρ):

    PSF_k(r; z) = |∫ P_k(u) exp(i2π z η(u)) exp(i2π u·r) d²u|²            (object µm, upright)

It differs from Eq. 6 only by the light a neighbouring lenslet spills into the EI (its diffraction
tail) and by the Fresnel approximation of the propagation over f_ml. We keep it factorised:

    PSF_k(r; z) = B_k(r − z·t_k; z),   t_k = <u/η(u)>_{|P_k|²}   (the mean tanθ·û vector)

- z·t_k is the parallax: the centroid of PSF_k is exactly the |P_k|²-weighted mean phase
  gradient of the pupil. It is applied as a Fourier phase ramp, so it is exact to sub-pixel.
- B_k (the defocus blur with the parallax removed) is small and stored per lenslet and depth on a
  ``support_px`` square, float32 (210 MB for 32 lenslets x 161 depths). A blur shared by all
  lenslets would not reach 1%: the curvature of η(u) varies across the pupil (an astigmatic
  blur), 1.3% relative L2 at |z| = 80 µm for the unclipped diagonal lenslets of the paper's
  optics, and the 16 edge lenslets clipped by the pupil differ by 3-50% (their own shapes).
- The pixel integration is the separable factor sinc(f_x) sinc(f_y) of the OTF (f in cycles/px).

Normalisation: a kernel holds the energy per pixel, as a fraction of the light through one
unclipped lenslet. Over the whole plane it sums to the lenslet's pupil fraction (1 inside the
pupil, less for the clipped edge lenslets); a finite window loses the diffraction tail (about 1.3%
outside the EI of the paper's optics, 2/(π v) of an Airy pattern at v = 2π NA_sub R/λ).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import cpu
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.pupil import Pupil, axial_frequency, mean_tilt, subaperture_pupil
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import DEFAULT_Z_UM


def _boxed_pupil(optics: Optics, lenslet, shape, du):
    """``subaperture_pupil`` on a small odd box, in natural order (offsets −m..m from its u_k)."""
    return tuple(np.fft.fftshift(a) for a in subaperture_pupil(optics, lenslet, shape, du))


# ------------------------------------------------------------------ fast form
class LensletPSF:
    """Per-lenslet EI kernels on the object-space EI grid, factorised as blur x parallax ramp.

    Parameters
    ----------
    optics : Optics
    lenslets : list of Lenslet, optional
        Default: every lenslet in the pupil.
    shape : (int, int), optional
        EI window (h, w), default the EI diameter (145 px for the paper's optics). Kernel pixel
        (i, j) samples the object offset ((j − w//2) + off_x, (i − h//2) + off_y)·pixel_um from
        the EI centre.
    pixel_um : float, optional
        Object pixel, µm (default the optics').
    offsets_px : ndarray, (K, 2), optional
        Sub-pixel offsets of each EI grid (x, y), px (default 0).
    support_px : int, optional
        Side of the stored blur, px (default: defocus blur at ``z_max_um`` plus 8 Airy radii).
    z_max_um : float, optional
        Largest |z| the kernels serve, µm (default 80).
    pixel_integration : bool
        Integrate over each camera pixel.

    Notes
    -----
    Blurs are computed per depth on first use and cached (``precompute`` fills the cache with a
    progress callback).
    """

    def __init__(
        self,
        optics: Optics,
        lenslets=None,
        shape=None,
        pixel_um=None,
        *,
        offsets_px=None,
        support_px=None,
        z_max_um=None,
        pixel_integration=True,
    ):
        self.optics = optics
        self.lenslets = list(nominal_lenslets(optics) if lenslets is None else lenslets)
        if not self.lenslets:
            raise SsdpcError("no lenslets given; calibrate the lattice or use nominal_lenslets(optics)")
        self.pixel_um = float(pixel_um or optics.object_pixel_um)
        if not self.pixel_um > 0:
            raise SsdpcError(f"pixel_um must be > 0, got {pixel_um}")
        if shape is None:
            r = int(math.floor(optics.ei_radius_um / optics.m_ei / self.pixel_um))
            shape = (2 * r + 1, 2 * r + 1)
        self.shape = tuple(int(s) for s in shape)
        if len(self.shape) != 2 or min(self.shape) < 3:
            raise SsdpcError(f"EI window shape must be two sizes >= 3 px, got {shape}")
        k = len(self.lenslets)
        self.offsets_px = np.zeros((k, 2)) if offsets_px is None else np.asarray(offsets_px, float)
        if self.offsets_px.shape != (k, 2):
            raise SsdpcError(f"offsets_px must have shape ({k}, 2) (x, y per lenslet), got {self.offsets_px.shape}")
        self.pixel_integration = bool(pixel_integration)
        self.support_px = int(support_px) if support_px else self._default_support(z_max_um)
        self.support_px = min(self.support_px, max(self.shape))
        # pupil grid: fine enough for the sub-aperture edge and wide enough for the blur; only the
        # box around u_k that holds the sub-aperture is kept (a few % of the grid)
        self._n = sfft.next_fast_len(max(2 * self.support_px, 256))
        du = 1.0 / (self._n * self.pixel_um)
        pupil = Pupil.of(optics)
        centres, radii, _ = pupil.lenslet_arrays(self.lenslets)  # each lenslet's own sub-aperture
        m = min(int(math.ceil(radii.max() / du)) + 2, self._n // 2 - 1)
        self._box = np.arange(-m, m + 1) % self._n
        shape_box = (2 * m + 1, 2 * m + 1)
        pupils, ux, uy = zip(*(_boxed_pupil(optics, ln, shape_box, du) for ln in self.lenslets))
        self.tilt = np.stack([mean_tilt(optics, p, a, b) for p, a, b in zip(pupils, ux, uy)])
        # P_k: real for the nominal optics, complex with the optics' aberrations
        self._pupil = np.stack(pupils).astype(np.complex64 if pupil.aberrated else np.float32)
        # parallax ramps act on the offsets from u_k; the defocus is exp(i2π z [η − η(u_k)])
        self._f = (np.arange(-m, m + 1) * du).astype(np.float32)
        eta_k = axial_frequency(centres[:, 0], centres[:, 1], optics)[:, None, None]
        self._deta = (axial_frequency(np.stack(ux), np.stack(uy), optics) - eta_k).astype(np.float32)
        # the soft pupil edge is a cell average: it multiplies the amplitude by sinc(x du) sinc(y du)
        f = sfft.fftfreq(self._n)
        self._deapodise = (1.0 / (np.sinc(f)[:, None] * np.sinc(f)[None, :])).astype(np.float32)
        self._cache: dict[float, np.ndarray] = {}

    def _default_support(self, z_max_um):
        """Odd square holding the geometric defocus blur plus 8 Airy radii of diffraction tail
        (truncation error below 0.1% relative L2 for the paper's optics)."""
        o = self.optics
        if z_max_um is None:
            z_max_um = max(abs(z) for z in DEFAULT_Z_UM)  # the default z range
        cos3 = (1.0 - (o.na / o.medium_index) ** 2) ** 1.5
        blur = abs(z_max_um) * o.subaperture_na / (o.medium_index * cos3)
        airy = 0.61 * o.wavelength_um / o.subaperture_na
        return 2 * int(math.ceil((blur + 8 * airy) / self.pixel_um)) + 1

    @property
    def fractions(self) -> np.ndarray:
        """Pupil fraction of each lenslet (what its kernel sums to over the whole plane)."""
        return np.array([ln.fraction for ln in self.lenslets])

    def shift_um(self, z) -> np.ndarray:
        """Parallax z·<u/η>_k (K, 2) (x, y) in object µm: toward the optical axis for z > 0.

        Parameters
        ----------
        z : float
            Depth, µm (z > 0: farther from the objective).

        Returns
        -------
        ndarray, float64, (K, 2)
        """
        return float(z) * self.tilt

    # ---------------------------------------------------------------- blurs
    def blur(self, z) -> np.ndarray:
        """B_k(r; z): the kernels with the parallax removed, (K, S, S) float32, centre at S//2.

        Parameters
        ----------
        z : float
            Depth, µm.

        Returns
        -------
        ndarray, float32, (K, S, S)
        """
        key = float(z)
        if key not in self._cache:
            self._cache[key] = self._compute_blur(key)
        return self._cache[key]

    def precompute(self, z_values, progress=None) -> None:
        """Compute and cache the blurs of these depths; ``progress(done, total)`` after each.

        Parameters
        ----------
        z_values : iterable of float
            Depths, µm.
        progress : callable, optional
            ``progress(done, total)``.
        """
        zs = np.atleast_1d(z_values)
        for i, z in enumerate(zs):
            self.blur(z)
            if progress is not None:
                progress(i + 1, len(zs))

    def clear_cache(self) -> None:
        """Drop the cached blurs (they can take hundreds of MB)."""
        self._cache.clear()

    def _compute_blur(self, z: float) -> np.ndarray:
        s = z * self.tilt  # parallax in µm, removed by the ramps
        ramp_x = np.exp(2j * np.pi * s[:, 0, None] * self._f[None, :]).astype(np.complex64)
        ramp_y = np.exp(2j * np.pi * s[:, 1, None] * self._f[None, :]).astype(np.complex64)
        theta = np.float32(2 * np.pi * z) * self._deta
        box = self._pupil * (np.cos(theta) + 1j * np.sin(theta)) * ramp_y[:, :, None] * ramp_x[:, None, :]
        q = np.zeros((len(box), self._n, self._n), np.complex64)
        q[:, self._box[:, None], self._box[None, :]] = box
        h = cpu().ifft2(q) * self._deapodise  # amplitude PSF x pixel²
        inten = (h.real**2 + h.imag**2) / (self.pixel_um**2 * math.pi * self.optics.subaperture_radius**2)
        sup = self.support_px
        idx = np.arange(sup) - sup // 2
        return np.ascontiguousarray(inten[:, idx[:, None], idx[None, :]], dtype=np.float32)

    # ------------------------------------------------------------- operators
    def otf(self, z, fft_shape) -> np.ndarray:
        """OTFs for a batched real-FFT convolution: (K, P, Q//2+1) complex64 for a scalar z,
        (K, Z, P, Q//2+1) for a sequence; kernel centre at index 0 (as deconvolution.kernels_to_otf).

        Parameters
        ----------
        z : float or sequence of float
            Depth(s), µm.
        fft_shape : (int, int)
            (P, Q) of the padded real FFT, px.

        Returns
        -------
        ndarray, complex64
            (K, P, Q//2+1) or (K, Z, P, Q//2+1).
        """
        fft_shape = tuple(int(n) for n in fft_shape)
        if np.ndim(z) == 0:
            return self._otf_one(float(z), fft_shape)
        out = np.empty((len(self.lenslets), len(z), fft_shape[0], fft_shape[1] // 2 + 1), np.complex64)
        for i, v in enumerate(z):
            out[:, i] = self._otf_one(float(v), fft_shape)
        return out

    def _otf_one(self, z, fft_shape):
        b = self.blur(z)
        p, qn = fft_shape
        sup = self.support_px
        if sup > p or sup > qn:
            raise SsdpcError(f"FFT shape {fft_shape} is smaller than the kernel support {sup}; use a larger one")
        pad = np.zeros((len(b), p, qn), np.float32)
        idx = np.arange(sup) - sup // 2  # blur centre -> index 0
        pad[:, (idx % p)[:, None], (idx % qn)[None, :]] = b
        otf = cpu().rfft2(pad)
        t = self.shift_um(z) / self.pixel_um - self.offsets_px  # shift of the blur, px (x, y)
        fy, fx = sfft.fftfreq(p), sfft.rfftfreq(qn)
        ramp_y = np.exp(-2j * np.pi * fy[None, :] * t[:, 1, None])
        ramp_x = np.exp(-2j * np.pi * fx[None, :] * t[:, 0, None])
        otf *= (ramp_y[:, :, None] * ramp_x[:, None, :]).astype(np.complex64)
        if self.pixel_integration:
            otf *= (np.sinc(fy)[:, None] * np.sinc(fx)[None, :]).astype(np.float32)
        return otf.astype(np.complex64, copy=False)

    def kernels(self, z) -> np.ndarray:
        """EI-window kernels (K, h, w) float32 for a scalar z, (K, Z, h, w) for a sequence.

        Parameters
        ----------
        z : float or sequence of float
            Depth(s), µm.

        Returns
        -------
        ndarray, float32
            (K, h, w) or (K, Z, h, w): each lenslet's share of a point's light per sensor pixel.
        """
        if np.ndim(z) != 0:
            return np.stack([self.kernels(float(v)) for v in z], axis=1)
        h, w = self.shape
        t = np.abs(self.shift_um(z) / self.pixel_um - self.offsets_px).max(axis=0)
        fft_shape = (
            sfft.next_fast_len(int(h + self.support_px + 2 * math.ceil(t[1])), real=True),
            sfft.next_fast_len(int(w + self.support_px + 2 * math.ceil(t[0])), real=True),
        )
        full = cpu().irfft2(self._otf_one(float(z), fft_shape), s=fft_shape)
        iy = (np.arange(h) - h // 2) % fft_shape[0]
        ix = (np.arange(w) - w // 2) % fft_shape[1]
        return np.ascontiguousarray(full[:, iy[:, None], ix[None, :]], dtype=np.float32)
