"""3D phase from the lenslet views by a linear inversion of their weak-object transfer functions.

Each flat-fielded view k holds the contrast c_k = I_k / I0_k − 1 of every slice of the sample,
each through its own defocused WOTF (DESIGN.md §4.1, paper Eqs. 2-4):

    F[c_k](u) = Σ_z H_k(u; z) / I0_k · F[φ_z](u)          (phase part, first order)

With few views this is under-determined along z; the Tikhonov solution (paper Eq. 7 generalised
from 2 DPC images to K views and Z slices) is, per spatial frequency u,

    φ(u) = Hᴴ W (H Hᴴ W + α I)⁻¹ c(u)        (K x K system, W = diag(I0_k / max I0))

so the per-frame cost is K FFTs, a small solve per frequency and Z inverse FFTs. The weights W
follow the shot noise: a dim view has a noisier normalised contrast. φ_z is the phase of a slab
of thickness dz, so Δn = λ φ_z / (2π dz) (DESIGN.md §4.4).
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from . import transfer
from .errors import SsdpcError
from .optics import Optics


class WotfInversion:
    """Operators built once per optics, lenslet set, view grid and z grid."""

    def __init__(self, optics: Optics, lenslets, shape, pixel_um, z_um, alpha: float, i0=None, progress=None):
        if not alpha > 0:
            raise SsdpcError(f"alpha must be > 0, got {alpha}")
        z_um = np.atleast_1d(np.asarray(z_um, float))
        _, h_phase, i0_model = transfer.lenslet_transfer_functions(optics, lenslets, shape, pixel_um, z_um=z_um)
        i0 = np.asarray(i0_model if i0 is None else i0, float)
        if np.any(i0_model <= 0):
            raise SsdpcError("a view without direct light cannot be inverted; leave dark-field lenslets out")
        self.w = np.sqrt(i0 / i0.max()).astype(np.float32)                           # sqrt of the noise weights
        hw = (h_phase * (self.w / i0_model)[:, None, None, None]).astype(np.complex64)  # (K, Z, ny, nx)
        del h_phase
        gram = np.einsum("kzyx,lzyx->yxkl", hw, np.conj(hw))                         # (ny, nx, K, K)
        scale = float(np.max(np.real(np.einsum("yxkk->yx", gram)))) / len(i0)
        self.alpha = float(alpha)
        self.alpha_abs = self.alpha * scale      # alpha is relative to the strongest view's |H|² summed over z
        eye = np.eye(len(i0), dtype=np.complex64)
        self.inv = np.linalg.inv(gram + self.alpha_abs * eye).astype(np.complex64)
        self.hw_conj = np.conj(hw)
        if progress is not None:
            progress(1, 1)

    def phase(self, contrast) -> np.ndarray:
        """(Z, ny, nx) phase per slab from the views' contrast (K, ny, nx)."""
        c = np.asarray(contrast, np.float32) * self.w[:, None, None]
        spec = sfft.fft2(c, workers=-1)                                               # (K, ny, nx)
        lam = np.einsum("yxkl,lyx->kyx", self.inv, spec)
        phi = np.einsum("kzyx,kyx->zyx", self.hw_conj, lam)
        return sfft.ifft2(phi, workers=-1).real.astype(np.float32)
