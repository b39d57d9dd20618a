"""The reference path: Richardson–Lucy the straightforward way, as light-field toolboxes do it.

For each lenslet half and each plane z it builds a full-frame PSF: a sensor-sized image that
holds the kernel of every lenslet of the half at that lenslet's elemental image (EI). One RL
iteration then convolves every object plane with its PSF by FFTs over the whole sensor and sums
over z (forward), and correlates the ratio image with every PSF over the whole sensor (adjoint).

It uses the fast path's kernels (``LensletPSF`` of the same ``Reconstructor``), object grid,
masks, start value and update, so the two paths compute the same thing and their outputs can
be compared; only the data structures differ: sensor-sized PSFs per half and plane and
sensor-sized FFTs here, per-lenslet kernels on the view grid and band-limited spectra in
``deconvolution.MultiViewRL``.

The layout of the elemental images on the sensor-sized canvas is in
:mod:`napari_ssdpc.validation.reference_layout`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from napari_ssdpc.backend import cpu
from napari_ssdpc.reconstruction.deconvolution import RLResult
from napari_ssdpc.reconstruction.dpc import phase_to_delta_n
from napari_ssdpc.reconstruction.stacks import Stacks
from napari_ssdpc.validation.reference_layout import Layout, full_frame_psf, layout, lenslet_kernels


class ReferenceRL:
    """One half's Richardson–Lucy with full-frame PSFs and whole-sensor FFT convolutions.

    Parameters
    ----------
    rec : Reconstructor
        Built with the Richardson-Lucy operators.
    half : {'up', 'down', 'left', 'right'}
    lay : Layout
    kernels : sequence of ndarray, optional
        Per plane, the lenslets' kernels (K, 2R_y+1, 2R_x+1); default the fast path's.
    progress : callable, optional
        ``progress(done, total)`` per plane of the PSF build.
    """

    def __init__(self, rec, half: str, lay: Layout, kernels=None, progress=None):
        self.lay = lay
        self.members = list(rec.views.halves[half])
        self.z = len(rec.z_um)
        self.view_mask = np.asarray(rec.views.view_mask, np.float32)
        t0 = time.perf_counter()
        self.otf = np.empty((self.z, lay.shape[0], lay.shape[1] // 2 + 1), np.complex64)
        for i, z in enumerate(rec.z_um):
            ker = lenslet_kernels(rec, z, lay) if kernels is None else kernels[i]
            self.otf[i] = cpu().rfft2(full_frame_psf(ker, self.members, lay))
            if progress is not None:
                progress(i + 1, self.z)
        self.mask = self.place(self.view_mask[self.members])
        norm = self.adjoint(self.mask)
        top = float(norm.max())
        self.support = (norm > 1e-3 * top).astype(np.float32)
        self.norm = np.maximum(norm, 1e-3 * top)
        self.build_seconds = time.perf_counter() - t0

    def place(self, views):
        """Views of the half's lenslets (K_h, ny, nx) -> a canvas image.

        Parameters
        ----------
        views : ndarray, (K_h, ny, nx)
            One view per lenslet of the half.

        Returns
        -------
        ndarray, float32, canvas shape
        """
        img = np.zeros(self.lay.shape, np.float32)
        for v, k in zip(views, self.members):
            img[self.lay.windows(k)] = v
        return img

    def read(self, img):
        """The half's views cut out of a canvas image (inverse of :meth:`place`).

        Parameters
        ----------
        img : ndarray, canvas shape

        Returns
        -------
        ndarray, (K_h, ny, nx)
        """
        return np.stack([img[self.lay.windows(k)] for k in self.members])

    def forward(self, obj):
        """Σ_z PSF_z ⊛ o_z over the whole canvas, one plane at a time: (Z, P, Q) linear -> canvas.

        Parameters
        ----------
        obj : ndarray, (Z, P, Q)
            Object planes on the linear grid.

        Returns
        -------
        ndarray, float, canvas shape
        """
        acc = np.zeros_like(self.otf[0])
        for i in range(self.z):
            spec = cpu().rfft2(obj[i], s=self.lay.shape)
            spec *= self.otf[i]
            acc += spec
        return cpu().irfft2(acc, s=self.lay.shape)

    def adjoint(self, img):
        """PSF_z ⋆ img over the whole canvas for every plane: canvas -> (Z, P, Q) linear.

        Parameters
        ----------
        img : ndarray, canvas shape

        Returns
        -------
        ndarray, float32, (Z, P, Q)
            Linear grid.
        """
        spec = cpu().rfft2(img)
        p, q = self.lay.fft_shape
        out = np.empty((self.z, p, q), np.float32)
        for i in range(self.z):
            prod = np.conj(self.otf[i])
            prod *= spec
            out[i] = cpu().irfft2(prod, s=self.lay.shape)[:p, :q]
        return out

    def run(self, views, iterations: int) -> RLResult:
        """Same start value and update as ``MultiViewRL.run``; returns the (Z, ny, nx) stack.

        Parameters
        ----------
        views : ndarray, (K_h, ny, nx)
            Preprocessed views of the half's lenslets.
        iterations : int

        Returns
        -------
        RLResult
            The stack (Z, ny, nx) and the relative change per iteration.
        """
        y = self.place(np.asarray(views, np.float32)) * self.mask
        mean = float(np.sum(y) / max(np.sum(self.mask), 1))
        obj = np.full((self.z,) + self.lay.fft_shape, mean / max(self.z, 1), np.float32) * self.support
        eps = np.float32(1e-6 * max(float(y.max()), 1e-12))
        history = []
        for _ in range(iterations):
            est = self.forward(obj)
            ratio = np.where(self.mask > 0, y / np.maximum(est, eps), 0).astype(np.float32)
            new = (obj * np.maximum(self.adjoint(ratio), 0) / self.norm).astype(np.float32)
            history.append(float(np.linalg.norm(new - obj) / max(np.linalg.norm(obj), 1e-30)))
            obj = new
        (oy, ox), (ny, nx) = self.lay.offset, self.lay.view_shape
        return RLResult(obj[:, oy : oy + ny, ox : ox + nx], history)


@dataclass
class ReferenceResult:
    """The reference path's reconstruction: stacks per half, Δn and phase (Z, ny, nx), the
    layout used and timings (s).

    Attributes
    ----------
    stacks : dict
        Half name -> RL stack, ndarray float32 (Z, ny, nx).
    delta_n : ndarray, (Z, ny, nx)
        Δn (unitless).
    phase : ndarray, (Z, ny, nx)
        Phase per slab, rad.
    layout : Layout
    timings : dict
        ``build_s``, ``preprocess_s``, ``rl_s``, ``dpc_s``, ``phase_s``, s.
    """

    stacks: dict
    delta_n: np.ndarray
    phase: np.ndarray
    layout: Layout
    timings: dict


def reconstruct_reference(rec, frame, canvas: str = "sensor", progress=None) -> ReferenceResult:
    """Reconstruct ``frame`` with the reference RL and the pipeline's own DPC and phase steps.

    Halves are built and run one after the other, so that only one half's full-frame PSFs
    (Z sensor-sized spectra) are held at a time. ``timings``: build_s (PSFs), preprocess_s, rl_s,
    dpc_s, phase_s.

    Parameters
    ----------
    rec : Reconstructor
        Built with Richardson-Lucy operators.
    frame : ndarray, (H, W)
        Raw frame.
    canvas : {'sensor', 'eis'}
        See :func:`layout`.
    progress : callable, optional
        ``progress(done, total, label)`` per plane of the PSF builds.

    Returns
    -------
    ReferenceResult
    """
    lay = layout(rec, canvas)
    t0 = time.perf_counter()
    views = rec.views(frame)
    pre = time.perf_counter() - t0
    stacks, build, run = {}, 0.0, 0.0
    for j, h in enumerate(rec.views.halves):
        op = ReferenceRL(
            rec,
            h,
            lay,
            progress=None if progress is None else (lambda i, n, j=j: progress(j * n + i, 4 * n, "reference PSF")),
        )
        build += op.build_seconds
        t0 = time.perf_counter()
        stacks[h] = op.run(views[op.members], rec.config.reconstruction.rl.iterations).stack
        run += time.perf_counter() - t0
        del op
    t0 = time.perf_counter()
    dpc, absorption = rec.stacks.dpc(stacks)
    t1 = time.perf_counter()
    phase = rec.method.solve(views, Stacks(stacks, dpc, absorption, {}, rec.stacks.h_dpc)).phase
    dn = phase_to_delta_n(phase, rec.optics.wavelength_um, rec.dz)
    return ReferenceResult(
        stacks,
        dn,
        phase,
        lay,
        {"build_s": build, "preprocess_s": pre, "rl_s": run, "dpc_s": t1 - t0, "phase_s": time.perf_counter() - t1},
    )


def max_relative_difference(a, b) -> float:
    """max |a − b| / max |b| (b the reference).

    Parameters
    ----------
    a, b : array_like
        Same shape; ``b`` is the reference.

    Returns
    -------
    float
    """
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-30))
