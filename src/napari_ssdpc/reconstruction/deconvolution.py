"""Richardson–Lucy deconvolution of light-field views into a z stack (paper §2, refs 67-68).

Model: view k is y_k = M · Σ_z h_{k,z} ⊛ o_z, with o ≥ 0 the (Z, ny, nx) intensity
stack, h_{k,z} the lenslet-k PSF at depth z, and M the mask of measured pixels (inside the
iris). Convolutions are linear (zero-padded real FFTs), batched over lenslets and planes;
per frequency the sums over z and k are small matrix products.

Speed (docs/performance.md): the OTF of a sub-aperture vanishes outside |f| ≤ 2ρ (the
autocorrelation of a pupil of radius ρ), so with a :class:`Band` the OTFs are stored, and the
sums over z and k computed, only on the box of frequencies that holds that disk (about a fifth
of the real-FFT grid for the paper's optics); the object FFTs skip the columns outside it. The
arrays live on the device of the :mod:`backend` (NumPy or CuPy) for the whole iteration.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import cpu, get_backend
from napari_ssdpc.blas import matmul
from napari_ssdpc.errors import SsdpcError


def padded_shape(view_shape, kernel_shape):
    """FFT shape for linear convolution, from scipy.fft.next_fast_len (real FFTs).

    Parameters
    ----------
    view_shape, kernel_shape : (int, int)
        (h, w) of a view and of a kernel, px.

    Returns
    -------
    (int, int)
    """
    return tuple(sfft.next_fast_len(int(a + b - 1), real=True) for a, b in zip(view_shape, kernel_shape))


def kernels_to_otf(kernels, fft_shape):
    """OTFs (K, Z, P, Q//2+1) of centred kernels (K, Z, kh, kw), rfft over the last two axes.

    Parameters
    ----------
    kernels : ndarray, (K, Z, kh, kw)
        Centred kernels.
    fft_shape : (int, int)
        (P, Q).

    Returns
    -------
    ndarray, complex64, (K, Z, P, Q//2+1)
    """
    kernels = np.asarray(kernels, dtype=np.float32)
    kh, kw = kernels.shape[-2:]
    pad = np.zeros(kernels.shape[:-2] + tuple(fft_shape), np.float32)
    pad[..., :kh, :kw] = kernels
    pad = np.roll(pad, (-(kh // 2), -(kw // 2)), axis=(-2, -1))  # kernel centre -> index 0
    return cpu().rfft2(pad).astype(np.complex64)


@dataclass(frozen=True)
class Band:
    """The box of an rfft2 spectrum on ``shape`` (P, Q) that holds the OTFs: rows 0..r and
    P−r..P−1 (frequencies |f_y| ≤ r/P) by columns 0..ncols−1. ``full`` keeps everything."""

    shape: tuple
    r: int
    ncols: int

    @classmethod
    def full(cls, shape) -> Band:
        """The whole rfft2 spectrum of ``shape``.

        Parameters
        ----------
        shape : (int, int)
            (P, Q).

        Returns
        -------
        Band
        """
        p, q = (int(v) for v in shape)
        return cls((p, q), p, q // 2 + 1)

    @classmethod
    def disk(cls, shape, radius) -> Band:
        """The box around the disk |f| ≤ ``radius`` (cycles per pixel); the full grid if it is larger.

        Parameters
        ----------
        shape : (int, int)
            (P, Q).
        radius : float
            Cycles per pixel.

        Returns
        -------
        Band
        """
        p, q = (int(v) for v in shape)
        r = int(math.floor(radius * p))
        c = int(math.floor(radius * q)) + 1
        if 2 * r + 1 >= p or c >= q // 2 + 1:
            return cls.full((p, q))
        return cls((p, q), r, c)

    @classmethod
    def box(cls, shape, m) -> Band:
        """The rfft2 half of a centred box of m = (my, mx) frequencies (odd; unshifted order
        −(m−1)/2 … (m−1)/2); the full grid if the box reaches the grid's size.

        Parameters
        ----------
        shape : (int, int)
            (P, Q).
        m : (int, int)
            (my, mx), odd.

        Returns
        -------
        Band
        """
        p, q = (int(v) for v in shape)
        my, mx = (int(v) for v in m)
        if my >= p or mx >= q:
            return cls.full((p, q))
        return cls((p, q), (my - 1) // 2, (mx - 1) // 2 + 1)

    @property
    def is_full(self) -> bool:
        """Whether the band is the whole spectrum."""
        return self.r >= self.shape[0]

    @property
    def box_shape(self) -> tuple:
        """(2r+1, ncols): the band's shape."""
        return (self.shape[0] if self.is_full else 2 * self.r + 1, self.ncols)

    @property
    def fraction(self) -> float:
        """Kept fraction of the rfft2 grid."""
        return self.box_shape[0] * self.ncols / (self.shape[0] * (self.shape[1] // 2 + 1))

    def take(self, spec, xp=np):
        """The band (..., 2r+1, ncols) of a spectrum (..., P, ncols or more).

        Parameters
        ----------
        spec : ndarray, complex, (..., P, ≥ ncols)
        xp : module
            NumPy or CuPy.

        Returns
        -------
        ndarray, complex, (..., 2r+1, ncols)
        """
        if self.is_full:
            return spec
        r = self.r
        return xp.concatenate((spec[..., : r + 1, : self.ncols], spec[..., -r:, : self.ncols]), axis=-2)

    def put(self, out, band) -> None:
        """Write a band into ``out`` (..., P, ≥ ncols); the rest of ``out`` is left as it is.

        Parameters
        ----------
        out : ndarray, complex, (..., P, ≥ ncols)
            Written in place.
        band : ndarray, complex, (..., 2r+1, ncols)
        """
        if self.is_full:
            out[...] = band
            return
        r = self.r
        out[..., : r + 1, : self.ncols] = band[..., : r + 1, :]
        out[..., -r:, : self.ncols] = band[..., r + 1 :, :]


@dataclass
class RLResult:
    """What Richardson-Lucy returns.

    Attributes
    ----------
    stack : ndarray, float32, (Z, ny, nx)
        Deconvolved intensity.
    relative_change : list of float
        ‖o_{i+1} − o_i‖ / ‖o_i‖ per iteration.
    stopped : bool
        ``should_stop()`` asked to stop early.
    """

    stack: np.ndarray  # (Z, ny, nx) deconvolved intensity
    relative_change: list = field(default_factory=list)  # ||o_{i+1} - o_i|| / ||o_i|| per iteration
    stopped: bool = False  # should_stop() asked to stop early


class MultiViewRL:
    """Richardson–Lucy for several views sharing one z stack.

    ``otf``: (K, Z, P, Q//2+1) OTFs of a real FFT of even width Q (kernel centre at index 0), or,
    with ``band``, only their band (K, Z, *band.box_shape) for an FFT of shape ``band.shape``.
    ``backend``: 'cpu' (NumPy, default), 'gpu' (CuPy) or a :class:`backend.Backend`.
    ``workspace``: a dict through which operators run one after the other share their FFT
    scratch buffers (one set per thread).
    """

    def __init__(
        self,
        otf,
        view_shape,
        mask=None,
        workers=-1,
        *,
        band: Band | None = None,
        backend=None,
        workspace: dict | None = None,
    ):
        self.bk = bk = get_backend(backend, workers)
        otf = np.asarray(otf)
        self.k, self.z = otf.shape[:2]
        if band is None:
            band = Band.full((otf.shape[2], 2 * (otf.shape[3] - 1)))
        if tuple(otf.shape[2:]) != band.box_shape:
            raise SsdpcError(
                f"OTFs of shape {otf.shape[2:]} do not fit the frequency band {band.box_shape}; rebuild the operators"
            )
        self.band = band
        self.fft_shape = tuple(band.shape)
        self.view_shape = tuple(view_shape)
        self.workers = workers
        # (F, K, Z): per frequency of the band a K x Z matrix, so that the sums over z and k are
        # batched matrix products
        box = int(np.prod(band.box_shape))
        self.otf = bk.asarray(
            np.ascontiguousarray(np.moveaxis(otf.reshape(self.k, self.z, box), -1, 0), dtype=np.complex64)
        )
        # per-thread scratch (freed with its thread), shared by the operators of one workspace
        self._local = ({} if workspace is None else workspace).setdefault("scratch", threading.local())
        m = np.ones(self.view_shape, np.float32) if mask is None else np.asarray(mask, np.float32)
        self.mask = bk.asarray(self._pad(np.broadcast_to(m, (self.k,) + self.view_shape)))
        norm = self.adjoint(self.mask)  # Hᵀ1
        top = float(norm.max())
        self.support = norm > 1e-3 * top  # object voxels some view sees
        bk.xp.maximum(norm, np.float32(1e-3 * top), out=norm)
        self._inv_norm = bk.xp.divide(np.float32(1.0), norm, out=norm)

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_local"] = None  # scratch buffers are not sent along
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._local = threading.local()

    def _pad(self, a):
        out = np.zeros(a.shape[:-2] + self.fft_shape, np.float32)
        out[..., : a.shape[-2], : a.shape[-1]] = a
        return out

    # ------------------------------------------------------------ FFTs on the band
    def _spectrum(self, a):
        """Band of rfft2(a): (N, P, Q) real -> (N, *box) complex. The column FFTs skip the
        columns outside the band."""
        bk = self.bk
        if self.band.is_full:
            return bk.rfft2(a)
        s = bk.rfft(a, axis=-1)[..., : self.band.ncols]
        return self.band.take(bk.fft_(s, axis=-2), bk.xp)

    def _image(self, band):
        """Inverse of ``_spectrum`` with zeros outside the band: (N, *box) -> (N, P, Q) real."""
        bk = self.bk
        p, q = self.fft_shape
        if self.band.is_full:
            return bk.irfft2(band, s=(p, q))
        n = band.shape[0]
        buffers = self._local.__dict__.setdefault("buffers", {})
        key = (bk.device, n, p, q, self.band.r, self.band.ncols)
        if key not in buffers:  # zero outside the band for good: only the band is ever written
            buffers[key] = (
                bk.xp.zeros((n, p, self.band.ncols), np.complex64),
                bk.xp.zeros((n, p, q // 2 + 1), np.complex64),
            )
        cols, half = buffers[key]
        self.band.put(cols, band)
        half[..., : self.band.ncols] = bk.ifft(cols, axis=-2)
        return bk.irfft(half, n=q, axis=-1)

    def forward(self, obj):
        """Σ_z h_{k,z} ⊛ o_z on the padded grid: (Z, P, Q) -> (K, P, Q).

        Parameters
        ----------
        obj : ndarray, float32, (Z, P, Q)

        Returns
        -------
        ndarray, float32, (K, P, Q)
        """
        xp = self.bk.xp
        o = self._spectrum(xp.asarray(obj, dtype=np.float32))  # (Z, *box)
        o = xp.ascontiguousarray(o.reshape(self.z, -1).T)[..., None]  # (F, Z, 1)
        v = matmul(self.otf, o)[..., 0]  # (F, K)
        return self._image(xp.ascontiguousarray(v.T).reshape((self.k,) + self.band.box_shape))

    def adjoint(self, views):
        """Σ_k h_{k,z} ⋆ r_k (correlation): (K, P, Q) -> (Z, P, Q).

        Parameters
        ----------
        views : ndarray, float32, (K, P, Q)

        Returns
        -------
        ndarray, float32, (Z, P, Q)
        """
        xp = self.bk.xp
        r = self._spectrum(xp.asarray(views, dtype=np.float32))  # (K, *box)
        r = xp.ascontiguousarray(xp.conj(r).reshape(self.k, -1).T)[:, None, :]  # (F, 1, K)
        a = matmul(r, self.otf)[:, 0, :]  # (F, Z): Σ_k conj(r_k) h_kz
        return self._image(xp.conj(a.T).reshape((self.z,) + self.band.box_shape))

    # ------------------------------------------------------------------- RL
    def run(self, views, iterations: int, init=None, progress=None, should_stop=None) -> RLResult:
        """Richardson-Lucy iterations of the multi-view model (paper Eq. 6).

        Parameters
        ----------
        views : ndarray, (K, h, w)
            Non-negative views, one per lenslet.
        iterations : int
        init : ndarray, (Z, h, w), optional
            Start (default: flat).
        progress : callable, optional
            ``progress(done, total, label)`` per iteration.
        should_stop : callable, optional
            Checked every iteration; True stops early.

        Returns
        -------
        RLResult
        """
        if iterations < 1:
            raise SsdpcError(f"Richardson-Lucy iterations must be >= 1, got {iterations}")
        views = np.asarray(views, np.float32)
        if views.shape != (self.k,) + self.view_shape:
            raise SsdpcError(
                f"views of shape {views.shape} do not match the operators "
                f"{(self.k,) + self.view_shape}; rebuild the operators for this calibration"
            )
        if np.any(views < 0):
            raise SsdpcError("Richardson-Lucy needs non-negative data; subtract the dark offset and clip at zero")
        bk, xp = self.bk, self.bk.xp
        y = bk.asarray(self._pad(views)) * self.mask  # zero outside the mask, so y / est is too
        if init is None:
            mean = float(y.sum()) / max(float(self.mask.sum()), 1.0)
            obj = xp.full((self.z,) + self.fft_shape, np.float32(mean / max(self.z, 1)), np.float32)
        else:
            obj = bk.asarray(init, np.float32).copy()
        obj *= self.support
        history, stopped = [], False
        eps = np.float32(1e-6 * max(float(y.max()), 1e-12))
        size = float(xp.linalg.norm(obj))
        for i in range(iterations):
            ratio = y / xp.maximum(self.forward(obj), eps)
            new = self.adjoint(ratio)  # o ← o · Hᵀ(y / H o) / Hᵀ1
            xp.maximum(new, 0, out=new)
            new *= self._inv_norm
            new *= obj
            obj -= new  # the change, in place
            change = float(xp.linalg.norm(obj))
            obj = new
            history.append(change / max(size, 1e-30))
            size = float(xp.linalg.norm(obj))
            if progress is not None:
                progress(i + 1, iterations)
            if should_stop is not None and should_stop():
                stopped = True
                break
        ny, nx = self.view_shape
        return RLResult(bk.to_host(obj[:, :ny, :nx]), history, stopped)
