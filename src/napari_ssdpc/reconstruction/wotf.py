"""3D phase from the lenslet views by a linear inversion of their weak-object transfer functions.

Each flat-fielded view k holds the contrast c_k = I_k / I0_k − 1 of every slice of the sample,
each through its own defocused WOTF (docs/conventions.md, paper Eqs. 2-4):

    F[c_k](u) = Σ_z H_k(u; z) / I0_k · F[φ_z](u)          (phase part, first order)

With few views this is under-determined along z; the Tikhonov solution (paper Eq. 7 generalised
from 2 DPC images to K views and Z slices) is, per spatial frequency u,

    φ(u) = Hᴴ W (H Hᴴ W + α I)⁻¹ c(u)        (K x K system, W = diag(I0_k / max I0))

so the per-frame cost is K FFTs, a small solve per frequency and Z inverse FFTs. The weights W
follow the shot noise: a dim view has a noisier normalised contrast. φ_z is the phase of a slab
of thickness dz, so Δn = λ φ_z / (2π dz) (docs/conventions.md).
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics import transfer
from napari_ssdpc.settings.optics import Optics


class WotfInversion:
    """Operators built once per optics, lenslet set, view grid and z grid.

    The WOTFs vanish beyond |u| = 2ρ (the sub-aperture's autocorrelation), where the solution
    is zero: the operators are kept, and the solve done, on that band of the spectrum only, and
    built a few planes at a time (docs/performance.md)."""

    def __init__(
        self, optics: Optics, lenslets, shape, pixel_um, z_um, alpha: float, i0=None, progress=None, chunk: int = 16
    ):
        if not alpha > 0:
            raise SsdpcError(f"alpha must be > 0, got {alpha}")
        z_um = np.atleast_1d(np.asarray(z_um, float))
        setup = transfer._LensletSetup(optics, lenslets, shape, pixel_um)
        i0_model = setup.i0
        i0 = np.asarray(i0_model if i0 is None else i0, float)
        if np.any(i0_model <= 0):
            raise SsdpcError("a view without direct light cannot be inverted; leave dark-field lenslets out")
        self.w = np.sqrt(i0 / i0.max()).astype(np.float32)  # sqrt of the noise weights
        self.shape = tuple(int(n) for n in shape)
        self._iy, self._ix = ((transfer._fft_indices(m) % n)[:, None] for m, n in zip(setup.m_out, self.shape))
        self._ix = self._ix.T
        k, nz = len(i0), len(z_um)
        self.hw_conj = np.empty((k, nz) + tuple(setup.m_out), np.complex64)  # (K, Z, band)
        gram = 0
        weight = (self.w / i0_model)[:, None, None, None].astype(np.float32)
        for start in range(0, nz, chunk):
            _, h_phase = setup.band(z_um[start : start + chunk])  # (z, K, band)
            hw = (np.swapaxes(h_phase, 0, 1) * weight).astype(np.complex64)
            gram = gram + np.einsum("kzyx,lzyx->yxkl", hw, np.conj(hw))  # (band, K, K)
            self.hw_conj[:, start : start + chunk] = np.conj(hw)
        scale = float(np.max(np.real(np.einsum("yxkk->yx", gram)))) / len(i0)
        self.alpha = float(alpha)
        self.alpha_abs = self.alpha * scale  # alpha is relative to the strongest view's |H|² summed over z
        eye = np.eye(len(i0), dtype=np.complex64)
        self.inv = np.linalg.inv(gram + self.alpha_abs * eye).astype(np.complex64)
        if progress is not None:
            progress(1, 1)

    def phase(self, contrast) -> np.ndarray:
        """(Z, ny, nx) phase per slab from the views' contrast (K, ny, nx)."""
        c = np.asarray(contrast, np.float32) * self.w[:, None, None]
        spec = sfft.fft2(c, workers=-1)[:, self._iy, self._ix]  # (K, band)
        lam = np.einsum("yxkl,lyx->kyx", self.inv, spec)
        phi = np.zeros((self.hw_conj.shape[1],) + self.shape, np.complex64)  # zero beyond the band
        phi[:, self._iy, self._ix] = np.einsum("kzyx,kyx->zyx", self.hw_conj, lam)
        return sfft.ifft2(phi, workers=-1).real.astype(np.float32)
