"""The views' first-order model, one small matrix per spatial frequency (paper Eqs. 2-4).

Each flat-fielded view k holds the contrast c_k = I_k / I0_k − 1 of every slab of the sample,
each through its own defocused phase WOTF (docs/conventions.md):

    ĉ_k(u) = Σ_z H_k(u; z) / I0_k · φ̂_z(u)

The WOTFs vanish beyond |u| = 2ρ (the autocorrelation of a sub-aperture of radius ρ), and views
and phase are real, so only the half spectrum of a real FFT inside that disk carries anything:
the box :class:`~napari_ssdpc.reconstruction.deconvolution.Band` keeps. Per frequency p of that
box the model is a K x Z matrix A_p; the operator stores all of them as one (P, K, Z) complex64
array, so every sum over planes or views is one batched matrix product (``@``, NumPy or CuPy) over
contiguous memory. Both phase methods (:mod:`.wotf` and :mod:`.regularised`) use one instance,
built once per optics, lenslets, view grid and z grid. It is built on the host and then lives
on the device of its :class:`~napari_ssdpc.backend.Backend` (NumPy or CuPy), as do
the arrays its methods return; the inversions copy their results back with ``bk.to_host``.

The views are weighted by w_k = √(I0_k / max I0): the normalised contrast of a dim view is
noisier (shot noise), so the weighted contrast has the same noise in every view.
"""

from __future__ import annotations

import copy
import math
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import Backend, get_backend
from napari_ssdpc.blas import matmul
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics import transfer
from napari_ssdpc.reconstruction.deconvolution import Band
from napari_ssdpc.settings.optics import Optics

__all__ = ["TransferFunctions", "ViewModel", "apply", "padded_planes"]


@runtime_checkable
class TransferFunctions(Protocol):
    """What a :class:`ViewModel` is built from: the views' weak-object transfer functions.

    The lenslet views of this microscope (:class:`~napari_ssdpc.physics.transfer.LensletSetup`,
    paper Eqs. 2-4) are one such set; a fitted pupil or another microscope's images (an LED
    array's half-disk patterns) are others: anything that gives each view's phase transfer
    function at any depth on the band of frequencies its intensity can hold.

    Attributes
    ----------
    i0 : ndarray, float, (K,)
        Each view's direct-light background in the model (what its contrast is normalised by).
    m_out : (int, int)
        The band grid (my, mx) the transfer functions are given on, unshifted FFT order.
    """

    i0: np.ndarray
    m_out: tuple[int, ...]

    def band(self, zs) -> tuple[np.ndarray, np.ndarray]:
        """(H_abs, H_phase), each (Z, K, my, mx), on the band grid.

        Parameters
        ----------
        zs : ndarray, (Z,)
            Depths, µm.
        """
        ...

    def embed(self, h) -> np.ndarray:
        """Transfer functions on the band grid placed on the whole image grid.

        Parameters
        ----------
        h : ndarray, (..., my, mx)
        """
        ...


class ViewModel:
    """A_p = w_k H_k(u_p; z) / I0_k on the half band, (P, K, Z) complex64.

    Built from any :class:`TransferFunctions`; :meth:`for_lenslets` builds the lenslet views'.

    Parameters
    ----------
    transfer : TransferFunctions
        The views' transfer functions (their ``i0`` is the model's direct light).
    shape : tuple of int
        (ny, nx) of a view, px.
    pixel_um : float
        Object-side pixel of the views, µm.
    z_um : array_like, shape (Z,)
        Slab centres, µm.
    i0 : array_like, shape (K,), optional
        Each view's measured direct light (flat frame); the model's by default. Sets the weights.
    progress : callable, optional
        ``progress(done, total, 'operators')`` while the planes are built.
    chunk : int
        Planes built at a time (memory).
    backend : {'cpu', 'gpu'} or Backend, optional
        Where the model lives and the inversions run (default: the CPU).

    Attributes
    ----------
    a : ndarray (NumPy or CuPy), complex64, shape (P, K, Z)
        The model per band frequency, on the backend's device.
    w : numpy.ndarray, float32, shape (K,)
        The views' weights.
    band : Band
        Where the P frequencies lie in an rfft2 spectrum of ``shape`` (rows by columns, row-major).
    multiplicity : ndarray (NumPy or CuPy), float32, shape (P,)
        How often each frequency appears in the full spectrum (1 for column 0, else 2): sums over
        the half band times this are sums over the whole spectrum (Parseval).
    """

    def __init__(
        self,
        transfer: TransferFunctions,
        shape,
        pixel_um,
        z_um,
        *,
        i0=None,
        progress=None,
        chunk: int = 16,
        backend: str | Backend | None = None,
    ):
        self.bk = bk = get_backend(backend)
        self.shape = tuple(int(n) for n in shape)
        self.pixel_um = float(pixel_um)
        self.z_um = np.atleast_1d(np.asarray(z_um, float))
        i0_model = np.asarray(transfer.i0, float)
        if np.any(i0_model <= 0):
            raise SsdpcError(
                "a lit view gets no direct light at this condenser NA: the calibration's lenslet centres were swapped "
                "or edited, or condenser_na is not the flat's; recalibrate on a white frame or set condenser_na"
            )
        i0 = np.asarray(i0_model if i0 is None else i0, float)
        self.w = np.sqrt(i0 / i0.max()).astype(np.float32)
        self.band = Band.box(self.shape, transfer.m_out)
        by, bx = self.band.box_shape
        k, nz = len(i0), len(self.z_um)
        weight = (self.w / i0_model).astype(np.float32)[None, :, None, None]
        a = np.empty((by * bx, k, nz), np.complex64)
        for start in range(0, nz, chunk):
            _, hp = transfer.band(self.z_um[start : start + chunk])  # (z, K, my, mx), unshifted order
            if self.band.is_full:
                hp = transfer.embed(hp)
            hp = (hp[..., :bx] * weight).astype(np.complex64)  # columns 0..bx−1: the half band
            a[:, :, start : start + len(hp)] = hp.reshape(len(hp), k, by * bx).transpose(2, 1, 0)
            if progress is not None:
                progress(min(start + chunk, nz), nz, "operators")
        mult = np.full(self.band.box_shape, 2.0, np.float32)
        mult[:, 0] = 1.0
        if self.shape[1] % 2 == 0 and bx == self.shape[1] // 2 + 1:
            mult[:, -1] = 1.0  # the Nyquist column of an even width
        self.a = bk.asarray(a)
        self.multiplicity = bk.asarray(mult.ravel())
        self._w = bk.asarray(self.w)

    @classmethod
    def for_lenslets(cls, optics: Optics, lenslets, shape, pixel_um, z_um, **kw) -> ViewModel:
        """The model of the lenslet views (paper Eqs. 2-4: each lenslet's sub-aperture of the pupil).

        Parameters
        ----------
        optics : Optics
        lenslets : list of Lenslet
            The lit lenslets, in the order of the views.
        shape, pixel_um, z_um, **kw
            As for :class:`ViewModel`.

        Returns
        -------
        ViewModel
        """
        shape = tuple(int(n) for n in shape)
        return cls(transfer.LensletSetup(optics, lenslets, shape, float(pixel_um)), shape, pixel_um, z_um, **kw)

    @property
    def n_views(self) -> int:
        """K, the number of views (lit lenslets)."""
        return self.a.shape[1]

    def planes(self, sl: slice) -> ViewModel:
        """The same model on a contiguous subset of its planes (shares nothing mutable).

        Parameters
        ----------
        sl : slice
            Planes to keep.

        Returns
        -------
        ViewModel
        """
        out = copy.copy(self)
        out.z_um = self.z_um[sl]
        out.a = self.bk.xp.ascontiguousarray(self.a[:, :, sl])
        return out

    def full_spectra(self, contrast) -> np.ndarray:
        """Weighted contrast spectra, (K, ny, nx//2+1) complex64 (unitary real FFT), on the device.

        Parameters
        ----------
        contrast : ndarray (host or device), shape (K, ny, nx)
            I_k / I0_k − 1 of each view.

        Returns
        -------
        ndarray, complex64, (K, ny, nx//2+1)
        """
        c = self.bk.asarray(contrast, np.float32) * self._w[:, None, None]
        return self.bk.rfft2(c, norm="ortho")

    def spectra(self, contrast) -> np.ndarray:
        """:meth:`full_spectra` on the band, (P, K).

        Parameters
        ----------
        contrast : ndarray, float32, (K, ny, nx)
            The views' contrast.

        Returns
        -------
        ndarray, complex64, (P, K)
        """
        return self.take(self.full_spectra(contrast))

    def take(self, spec) -> np.ndarray:
        """(n, ny, nx//2+1) spectra -> their band, (P, n).

        Parameters
        ----------
        spec : ndarray, complex, (n, ny, nx//2+1)

        Returns
        -------
        ndarray, complex, (P, n)
        """
        band = self.band.take(spec, self.bk.xp)
        return band.reshape(band.shape[0], -1).T

    def put(self, values, lead: int, dtype=np.complex64) -> np.ndarray:
        """(P, n) band values -> (n, ny, nx//2+1) spectra, zero beyond the band.

        Parameters
        ----------
        values : ndarray, complex, (P, n)
        lead : int
            n.
        dtype : dtype

        Returns
        -------
        ndarray, (n, ny, nx//2+1)
        """
        out = self.bk.xp.zeros((lead, self.shape[0], self.shape[1] // 2 + 1), dtype)
        self.band.put(out, values.T.reshape((lead,) + self.band.box_shape))
        return out

    def images(self, values) -> np.ndarray:
        """(P, n) band values -> (n, ny, nx) real images (unitary inverse FFT), float32.

        Parameters
        ----------
        values : ndarray, complex, (P, n)

        Returns
        -------
        ndarray, float32, (n, ny, nx)
        """
        spec = self.put(values, values.shape[1])
        return self.bk.irfft2(spec, s=self.shape, norm="ortho").astype(np.float32)

    def forward(self, phi_band) -> np.ndarray:
        """A φ̂ per band frequency: (P, Z) -> (P, K).

        Parameters
        ----------
        phi_band : ndarray, complex, (P, Z)
            The phase's band values, rad.

        Returns
        -------
        ndarray, complex, (P, K)
            The views' contrast on the band.
        """
        return apply(self.a, phi_band)


def apply(m, x) -> np.ndarray:
    """One matrix per band frequency times one vector each: (P, M, N) @ (P, N) -> (P, M).

    Parameters
    ----------
    m : ndarray (NumPy or CuPy), (P, M, N)
    x : ndarray (same module), (P, N)

    Returns
    -------
    ndarray, (P, M)
    """
    return matmul(m, x[:, :, None])[:, :, 0]


def padded_planes(z_um, r_z_um: float, pad_um: float | None = None) -> tuple[np.ndarray, slice]:
    """The z grid the TV solve runs on: ``z_um`` padded beyond each end, to a fast FFT length.

    A padding plane may hold what the views see of objects beyond the requested range (it is
    cropped from the output), so that those objects do not pile up in the end planes, and the
    padding decouples the two ends, which the FFT along z would otherwise join.

    Parameters
    ----------
    z_um : array_like, shape (Z,)
        The requested slab centres, µm (evenly spaced).
    r_z_um : float
        Axial resolution, µm: the default padding on each side.
    pad_um : float, optional
        Padding on each side, µm (at least 4 planes).

    Returns
    -------
    zs : ndarray, shape (Z + padding,)
        The padded grid, µm.
    planes : slice
        Where ``z_um`` lies in ``zs``.
    """
    z_um = np.atleast_1d(np.asarray(z_um, float))
    if len(z_um) < 2:
        return z_um, slice(0, len(z_um))
    dz = float(z_um[1] - z_um[0])
    pad = max(4, int(math.ceil((r_z_um if pad_um is None else pad_um) / dz)))
    nz = sfft.next_fast_len(len(z_um) + 2 * pad)  # the z FFTs run on every iteration
    lo = (nz - len(z_um)) // 2
    return z_um[0] + dz * (np.arange(nz) - lo), slice(lo, lo + len(z_um))
