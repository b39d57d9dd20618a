"""Array backend: NumPy on the CPU (default), CuPy on a CUDA GPU when asked and present.

The foundation every computing layer stands on (physics, calibration, reconstruction, simulation):
code takes a :class:`Backend` and writes ``bk.xp`` where it would write ``np`` and ``bk.fft2(...)``
where it would write ``scipy.fft.fft2(...)``; the same lines then run on either device. This module
is the one FFT entry of the package: on the CPU every transform runs on all cores
(:func:`cpu` for code that only ever runs there). Arrays made by ``bk.xp`` stay on the device
until ``bk.to_host`` copies them back, so the iterations of a solver never leave the GPU.

    bk = get_backend("gpu")        # SsdpcError with the fix when CuPy or a GPU is missing
    a = bk.asarray(views)          # host -> device (a no-op on the CPU)
    spec = bk.rfft2(a)             # scipy.fft (all cores) or cupyx.scipy.fft (cuFFT)
    out = bk.to_host(spec)         # device -> host (a no-op on the CPU)
"""

from __future__ import annotations

import functools
import importlib
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from napari_ssdpc.errors import SsdpcError

__all__ = [
    "DEVICES",
    "GPU_INSTALL",
    "Backend",
    "cpu",
    "get_backend",
    "gpu_available",
    "in_threads",
]

DEVICES = ("cpu", "gpu")
GPU_INSTALL = "pip install 'napari-ssdpc[gpu]' (CuPy for CUDA 12)"


@dataclass(frozen=True)
class Backend:
    """One device: its array module ``xp`` and FFT module ``fft``."""

    device: str  # 'cpu' or 'gpu'
    xp: Any  # numpy or cupy
    fft: Any  # scipy.fft or cupyx.scipy.fft
    workers: int = -1  # scipy.fft threads (CPU only)
    name: str = ""  # what it runs on, for reports

    def __reduce__(self):  # modules do not pickle: rebuild on the other side
        return (get_backend, (self.device, self.workers))

    @property
    def is_gpu(self) -> bool:
        """Whether arrays live on a GPU (CuPy)."""
        return self.device == "gpu"

    # ----------------------------------------------------------- transfers
    def asarray(self, a, dtype=None):
        """``a`` on this device (no copy when it is already there with that dtype).

        Parameters
        ----------
        a : array_like
        dtype : dtype, optional

        Returns
        -------
        ndarray (NumPy or CuPy)
        """
        return self.xp.asarray(a, dtype=dtype)

    def to_host(self, a):
        """A NumPy array of ``a`` (a device -> host copy on the GPU).

        Parameters
        ----------
        a : ndarray (NumPy or CuPy)

        Returns
        -------
        numpy.ndarray
        """
        if self.is_gpu and not isinstance(a, np.ndarray):
            return self.xp.asnumpy(a)
        return np.asarray(a)

    def synchronize(self) -> None:
        """Wait for queued device work (for honest timings on the GPU)."""
        if self.is_gpu:
            self.xp.cuda.get_current_stream().synchronize()

    # ----------------------------------------------------------------- FFT
    def _kw(self, norm):
        kw = {} if self.is_gpu else {"workers": self.workers}
        return kw if norm is None else {**kw, "norm": norm}

    def rfft2(self, a, s=None, norm=None):
        """Real 2D FFT over the last two axes (threaded on the CPU).

        Parameters
        ----------
        a : ndarray, real, (..., P, Q)
        s : (int, int), optional
            Padded shape.
        norm : {None, 'ortho'}
            As in scipy.fft.

        Returns
        -------
        ndarray, complex, (..., P, Q//2+1)
        """
        return self.fft.rfft2(a, s=s, **self._kw(norm))

    def irfft2(self, a, s, norm=None):
        """Inverse of :meth:`rfft2`.

        Parameters
        ----------
        a : ndarray, complex, (..., P, Q//2+1)
        s : (int, int)
            Output shape (P, Q).
        norm : {None, 'ortho'}

        Returns
        -------
        ndarray, real, (..., P, Q)
        """
        return self.fft.irfft2(a, s=s, **self._kw(norm))

    def fft2(self, a, s=None, norm=None, overwrite_x: bool = False):
        """Complex 2D FFT over the last two axes, (..., P, Q) -> complex (..., P, Q) (or ``s``).

        Parameters
        ----------
        a : ndarray
        s : (int, int), optional
        norm : {None, 'ortho'}
        overwrite_x : bool
            ``a`` may be destroyed (saves a copy of a large complex array on the CPU).
        """
        return self.fft.fft2(a, s=s, overwrite_x=overwrite_x, **self._kw(norm))

    def ifft2(self, a, s=None, norm=None, overwrite_x: bool = False):
        """Inverse of :meth:`fft2` over the last two axes, complex.

        Parameters
        ----------
        a : ndarray, complex
        s : (int, int), optional
        norm : {None, 'ortho'}
        overwrite_x : bool
            As :meth:`fft2`.
        """
        return self.fft.ifft2(a, s=s, overwrite_x=overwrite_x, **self._kw(norm))

    def rfftn(self, a, norm=None):
        """Real FFT over every axis.

        Parameters
        ----------
        a : ndarray, real
        norm : {None, 'ortho'}

        Returns
        -------
        ndarray, complex, the last axis n//2+1 long
        """
        return self.fft.rfftn(a, **self._kw(norm))

    def irfftn(self, a, s, norm=None):
        """Inverse of :meth:`rfftn`.

        Parameters
        ----------
        a : ndarray, complex
        s : tuple of int
            Output shape.
        norm : {None, 'ortho'}

        Returns
        -------
        ndarray, real, shape ``s``
        """
        return self.fft.irfftn(a, s=s, **self._kw(norm))

    def rfft(self, a, axis=-1):
        """Real 1D FFT along ``axis``.

        Parameters
        ----------
        a : ndarray, real
        axis : int

        Returns
        -------
        ndarray, complex
        """
        return self.fft.rfft(a, axis=axis, **self._kw(None))

    def irfft(self, a, n, axis=-1):
        """Inverse of :meth:`rfft`.

        Parameters
        ----------
        a : ndarray, complex
        n : int
            Output length.
        axis : int

        Returns
        -------
        ndarray, real
        """
        return self.fft.irfft(a, n=n, axis=axis, **self._kw(None))

    def fft_(self, a, n=None, axis=-1):
        """Complex 1D FFT along ``axis``.

        Parameters
        ----------
        a : ndarray
        n : int, optional
            Transform length.
        axis : int

        Returns
        -------
        ndarray, complex
        """
        return self.fft.fft(a, n=n, axis=axis, **self._kw(None))

    def ifft(self, a, n=None, axis=-1, norm=None):
        """Inverse of :meth:`fft_`: complex, along ``axis``.

        Parameters
        ----------
        a : ndarray
        n, axis
            As :meth:`fft_`.
        norm : {None, 'ortho'}
        """
        return self.fft.ifft(a, n=n, axis=axis, **self._kw(norm))


@functools.cache
def _cpu(workers=-1) -> Backend:
    import platform

    import scipy.fft

    return Backend("cpu", np, scipy.fft, workers, f"NumPy/SciPy on {platform.processor() or platform.machine()}")


def _import(name):
    """Import hook (tests replace it to simulate a missing CuPy)."""
    return importlib.import_module(name)


def _gpu() -> Backend:
    try:
        cp = _import("cupy")
        cufft = _import("cupyx.scipy.fft")
    except ImportError:
        raise SsdpcError(
            f"--device gpu needs CuPy, which is not installed; {GPU_INSTALL}, or use --device cpu"
        ) from None
    try:
        n = int(cp.cuda.runtime.getDeviceCount())
    except Exception:  # CuPy raises its own CUDARuntimeError when the driver is missing
        n = 0
    if n < 1:
        raise SsdpcError("--device gpu: CuPy found no CUDA GPU (check the driver with nvidia-smi), or use --device cpu")
    try:
        props = cp.cuda.runtime.getDeviceProperties(cp.cuda.Device().id)
        name = props["name"].decode() if isinstance(props["name"], bytes) else str(props["name"])
    except Exception:
        name = "CUDA GPU"
    return Backend("gpu", cp, cufft, -1, f"CuPy on {name}")


def get_backend(device: str | Backend | None = "cpu", workers: int = -1) -> Backend:
    """The backend of ``device`` ('cpu' or 'gpu'; a Backend is returned as it is).

    Parameters
    ----------
    device : {'cpu', 'gpu'} or Backend, optional
        None means 'cpu'.
    workers : int
        FFT threads on the CPU (-1: all cores).

    Returns
    -------
    Backend
    """
    if isinstance(device, Backend):
        return device
    device = "cpu" if device is None else str(device).lower()
    if device not in DEVICES:
        raise SsdpcError(f"unknown device '{device}'; use one of {', '.join(DEVICES)}")
    return _gpu() if device == "gpu" else _cpu(workers)


def cpu() -> Backend:
    """The CPU backend (NumPy, SciPy's FFTs on all cores): for code that only ever runs there.

    Returns
    -------
    Backend
    """
    return _cpu(-1)


def gpu_available() -> bool:
    """True when CuPy is installed and sees at least one CUDA GPU."""
    try:
        _gpu()
    except SsdpcError:
        return False
    return True


@functools.cache
def _pool(parts: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(parts)


def in_threads(fn, n: int) -> list:
    """``fn(slice)`` over ``range(n)`` cut into one part per core, in threads of one shared pool:
    NumPy's elementwise operations release the GIL, so the parts run side by side.

    Parameters
    ----------
    fn : callable
        ``fn(part)`` for a slice of ``range(n)``.
    n : int
        Length of the range.

    Returns
    -------
    list
        ``fn``'s results, one per part, in order.
    """
    parts = max(1, min(os.cpu_count() or 1, n))
    bounds = np.linspace(0, n, parts + 1).astype(int)
    slices = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]
    if parts == 1:
        return [fn(slices[0])]
    return list(_pool(parts).map(fn, slices))
