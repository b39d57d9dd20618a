"""Richardson–Lucy deconvolution of light-field views into a z stack (paper §2, refs 67-68).

Model: view k is y_k = M · Σ_z h_{k,z} ⊛ o_z, with o ≥ 0 the (Z, ny, nx) intensity
stack, h_{k,z} the lenslet-k PSF at depth z, and M the mask of measured pixels (inside the
iris). Convolutions are linear (zero-padded real FFTs), batched over lenslets and planes;
per frequency the sums over z and k are small matrix products.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from .errors import SsdpcError


def padded_shape(view_shape, kernel_shape):
    """FFT shape for linear convolution, from scipy.fft.next_fast_len (real FFTs)."""
    return tuple(sfft.next_fast_len(int(a + b - 1), real=True) for a, b in zip(view_shape, kernel_shape))


def kernels_to_otf(kernels, fft_shape, workers=-1):
    """OTFs (K, Z, P, Q//2+1) of centred kernels (K, Z, kh, kw), rfft over the last two axes."""
    kernels = np.asarray(kernels, dtype=np.float32)
    kh, kw = kernels.shape[-2:]
    pad = np.zeros(kernels.shape[:-2] + tuple(fft_shape), np.float32)
    pad[..., :kh, :kw] = kernels
    pad = np.roll(pad, (-(kh // 2), -(kw // 2)), axis=(-2, -1))  # kernel centre -> index 0
    return sfft.rfft2(pad, workers=workers).astype(np.complex64)


@dataclass
class RLResult:
    stack: np.ndarray                      # (Z, ny, nx) deconvolved intensity
    relative_change: list = field(default_factory=list)  # ||o_{i+1} - o_i|| / ||o_i|| per iteration
    stopped: bool = False                  # should_stop() asked to stop early


class MultiViewRL:
    """Richardson–Lucy for several views sharing one z stack."""

    def __init__(self, otf, view_shape, mask=None, workers=-1):
        self.otf = np.ascontiguousarray(np.moveaxis(otf, (0, 1), (-2, -1)))  # (P, Qr, K, Z)
        self.k, self.z = otf.shape[:2]
        self.fft_shape = (otf.shape[2], 2 * (otf.shape[3] - 1))
        self.view_shape = tuple(view_shape)
        self.workers = workers
        m = np.ones(self.view_shape, np.float32) if mask is None else np.asarray(mask, np.float32)
        self.mask = self._pad(np.broadcast_to(m, (self.k,) + self.view_shape))
        norm = self.adjoint(self.mask)
        self.support = (norm > 1e-3 * norm.max()).astype(np.float32)  # object voxels some view sees
        self.norm = np.maximum(norm, 1e-3 * norm.max())

    def _pad(self, a):
        out = np.zeros(a.shape[:-2] + self.fft_shape, np.float32)
        out[..., : a.shape[-2], : a.shape[-1]] = a
        return out

    def forward(self, obj):
        """Σ_z h_{k,z} ⊛ o_z on the padded grid: (Z, P, Q) -> (K, P, Q)."""
        o = sfft.rfft2(obj, workers=self.workers)                       # (Z, P, Qr)
        v = np.matmul(self.otf, np.moveaxis(o, 0, -1)[..., None])[..., 0]  # (P, Qr, K)
        return sfft.irfft2(np.moveaxis(v, -1, 0), s=self.fft_shape, workers=self.workers)

    def adjoint(self, views):
        """Σ_k h_{k,z} ⋆ r_k (correlation): (K, P, Q) -> (Z, P, Q)."""
        r = sfft.rfft2(views, workers=self.workers)                     # (K, P, Qr)
        v = np.matmul(np.conj(np.swapaxes(self.otf, -1, -2)), np.moveaxis(r, 0, -1)[..., None])[..., 0]
        return sfft.irfft2(np.moveaxis(v, -1, 0), s=self.fft_shape, workers=self.workers)

    def run(self, views, iterations: int, init=None, progress=None, should_stop=None) -> RLResult:
        if iterations < 1:
            raise SsdpcError(f"Richardson-Lucy iterations must be >= 1, got {iterations}")
        views = np.asarray(views, np.float32)
        if views.shape != (self.k,) + self.view_shape:
            raise SsdpcError(f"views of shape {views.shape} do not match the operators "
                             f"{(self.k,) + self.view_shape}; rebuild the operators for this calibration")
        if np.any(views < 0):
            raise SsdpcError("Richardson-Lucy needs non-negative data; subtract the dark offset and clip at zero")
        y = self._pad(views) * self.mask
        if init is None:
            mean = float(np.sum(y) / max(np.sum(self.mask), 1))
            init = np.full((self.z,) + self.fft_shape, mean / max(self.z, 1), np.float32)
        obj = np.asarray(init, np.float32) * self.support
        history, stopped = [], False
        eps = np.float32(1e-6 * max(float(y.max()), 1e-12))
        for i in range(iterations):
            est = self.forward(obj)
            ratio = np.where(self.mask > 0, y / np.maximum(est, eps), 0).astype(np.float32)
            new = obj * np.maximum(self.adjoint(ratio), 0) / self.norm
            history.append(float(np.linalg.norm(new - obj) / max(np.linalg.norm(obj), 1e-30)))
            obj = new.astype(np.float32)
            if progress is not None:
                progress(i + 1, iterations)
            if should_stop is not None and should_stop():
                stopped = True
                break
        ny, nx = self.view_shape
        return RLResult(obj[:, :ny, :nx], history, stopped)
