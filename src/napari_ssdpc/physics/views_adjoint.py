"""The misfit of the multislice views and its gradients, back-propagated by hand through the forward
pass of :class:`~napari_ssdpc.physics.views_multislice.ViewsMultislice` (which mixes this class in).

- :meth:`ViewsAdjoint.misfit`: ½ Σ_k ‖W (I_k / I0_k − m_k)‖² and its gradient with respect to every
  voxel's Δn: with u_i the field just after screen i and G_i its gradient (∂L/∂u_i* x 2),
  ∂L/∂Δn_i = (2π δ / λ) Σ_j Im(u_i* G_i), and G_{i−1} = H_δ* ⊛ (t_i* G_i).
- :meth:`ViewsAdjoint.pupil_misfit`: its gradient with respect to the pupil's terms (the objective's
  Zernike coefficients and each lenslet's defocus, docs/aberrations.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["ViewsAdjoint"]


class ViewsAdjoint:
    """The adjoint of the multislice views: mixed into ``ViewsMultislice``, whose arrays (fields,
    kernels, crops, weights) it reads."""

    # what the forward model provides (``ViewsMultislice.__init__`` and its forward pass)
    xp: Any
    rdtype: Any
    _i0: Any
    _interpolate: Any
    _intensity: Callable

    def misfit(self, dn, measured, weight=None):
        """½ Σ_k ‖W (I_k / I0_k − m_k)‖² and its gradient with respect to Δn.

        Parameters
        ----------
        dn : ndarray, (Z, ny, nx)
            Δn of every voxel on the model grid, dimensionless.
        measured : ndarray, (K, h, w)
            The flat-fielded views on the ROI (:meth:`crop`).
        weight : ndarray, broadcastable to (K, h, w), optional
            W² per pixel (e.g. the field stop, 0/1, or inverse variances); default 1.

        Returns
        -------
        value : float
            The misfit, (flat-field units)².
        grad : ndarray, (Z, ny, nx)
            ∂misfit/∂Δn of every voxel, in the array module of the model.
        """
        value, grad, _, _ = self.misfit_and_pupil(dn, measured, weight, noll=None)
        return value, grad

    def misfit_and_pupil(self, dn, measured, weight=None, noll=(5, 6, 7, 8, 11)):
        """The misfit of :meth:`misfit`, its gradient with respect to Δn and to the pupil's terms, from
        one forward and one backward pass (the fit of the pupil to beads moves both).

        Parameters
        ----------
        dn, measured, weight
            As :meth:`misfit`.
        noll : sequence of int or None
            As :meth:`pupil_misfit`; None: the pupil's gradients are not computed (returned as None).

        Returns
        -------
        value : float
        grad : ndarray, (Z, ny, nx)
            ∂misfit/∂Δn.
        grad_zernike : ndarray, float64, (len(noll),) or None
        grad_defocus : ndarray, float64, (K,) or None
        """
        xp = self.xp
        screens = self._screens(dn)
        n_fields = len(screens) * self.substeps * self.n_sources * self.n * self.n
        keep = n_fields * self.cdtype.itemsize / 2**20 <= self.memory_mb
        value, g_i, store = self._residual(screens, measured, weight, keep)
        grad = xp.zeros((len(screens) * self.substeps, self.n, self.n), self.rdtype)
        pupil = None if noll is None else (np.zeros(len(noll)), np.zeros(self.view_shape[0]))
        for sl, st in zip(self._chunks(), store):
            g, kept = st if st is not None else self._propagate_chunk(screens, sl, True)
            self._backward_chunk(screens, sl, g, kept, g_i, grad)
            if pupil is not None:
                self._pupil_chunk(sl, g, g_i, noll, *pupil)
        grad = grad.reshape(len(screens), self.substeps, self.n, self.n).sum(axis=1)[::-1]
        gz, gd = (None, None) if pupil is None else pupil
        return value, xp.ascontiguousarray(grad), gz, gd

    def _residual(self, screens, measured, weight, keep: bool):
        """The misfit, ∂L/∂I on the crop grid (K, m, m) and, with ``keep``, what the backward pass needs."""
        xp = self.xp
        acc, store = self._intensity(screens, keep)
        res = self._interpolate(acc) / self._i0 - xp.asarray(measured, self.rdtype)
        wres = res if weight is None else res * xp.asarray(weight, self.rdtype)
        return 0.5 * float(xp.sum(res * wres)), self._interpolate.adjoint(wres / self._i0), store

    def pupil_misfit(self, dn, measured, weight=None, noll=(5, 6, 7, 8, 11)):
        """The misfit of :meth:`misfit` and its gradient with respect to the pupil's terms: the
        objective's Zernike coefficients and each lenslet's defocus (docs/aberrations.md).

        The pupil's phase φ enters every lenslet field g = ifft(c · A e^{iφ}) (c the crop of the exit
        spectrum); with X = fft(g) and P = fft(∂L/∂g* x 2) / m², ∂L/∂φ = −Im(X P*) at every crop
        sample, and φ = 2π [Σ_j c_j Z_j(u) + d_k |u − u_k|² / ρ_k²] is linear in the terms. The
        direct light I0_k does not depend on φ.

        Parameters
        ----------
        dn, measured, weight
            As :meth:`misfit`.
        noll : sequence of int
            The Noll indices of the objective's terms (piston, tilts and defocus move the objects,
            not the pupil: left out by default).

        Returns
        -------
        value : float
            The misfit, (flat-field units)².
        grad_zernike : ndarray, float64, (len(noll),)
            ∂misfit/∂c_j, per wave.
        grad_defocus : ndarray, float64, (K,)
            ∂misfit/∂d_k, per wave at the sub-aperture's edge.
        """
        screens = self._screens(dn)
        value, g_i, _ = self._residual(screens, measured, weight, False)
        gz, gd = np.zeros(len(noll)), np.zeros(self.view_shape[0])
        for sl in self._chunks():
            g, _ = self._propagate_chunk(screens, sl, False)
            self._pupil_chunk(sl, g, g_i, noll, gz, gd)
        return value, gz, gd

    def _pupil_chunk(self, sl, g, g_i, noll, gz, gd):
        """Add the source points ``sl``'s part of ∂L/∂c_j and ∂L/∂d_k to ``gz`` and ``gd``."""
        from napari_ssdpc.physics.zernike import zernike

        xp, two_pi = self.xp, 2 * math.pi
        gg = (2 * self._wgt[sl][..., None, None]) * g_i[None, None] * g
        dphi = -xp.imag(self.bk.fft2(g) * xp.conj(self.bk.fft2(gg))) / (self.m * self.m)  # (s, Q, K, m, m)
        ux, uy = self._ux[sl][..., None, :], self._uy[sl][..., :, None]
        r = xp.hypot(ux, uy) / self.pupil.cutoff
        theta = xp.arctan2(uy, ux)
        for i, j in enumerate(noll):
            gz[i] += two_pi * float(xp.sum(dphi * xp.where(r <= 1, zernike(j, xp.minimum(r, 1.0), theta), 0.0)))
        q = ((ux - self._uk[0]) ** 2 + (uy - self._uk[1]) ** 2) / (self._rho_k * self._rho_k)
        gd += two_pi * np.asarray(self.bk.to_host(xp.sum(dphi * q, axis=(0, 1, 3, 4))), float)

    def _backward_chunk(self, screens, sl, g, kept, g_i, grad):
        """Add the source points ``sl``'s part of ∂L/∂Δn per slab to ``grad`` (far side first)."""
        xp, n, s = self.xp, self.n, sl.stop - sl.start
        # I = Σ s_jk |g|²: ∂L/∂g* x 2 = 2 s_jk (∂L/∂I) g; g = ifft_m(crop · F): its adjoint is fft_m / m²
        gg = (2 * self._wgt[sl][..., None, None]) * g_i[None, None] * g
        gc = (self.bk.fft2(gg) * xp.conj(self._pair_kernel(sl))).sum(axis=1) / (self.m * self.m)
        j, r, c = self._gather(sl)
        flat = ((j * n + r) * n + c).ravel()
        spec = xp.bincount(flat, weights=gc.real.ravel(), minlength=s * n * n) + 1j * xp.bincount(
            flat, weights=gc.imag.ravel(), minlength=s * n * n
        )
        spec = spec.reshape(s, n, n).astype(self.cdtype)
        gu = self.bk.ifft2(spec) * (n * n)  # fftᴴ = n² ifft
        for i in range(len(kept) - 1, -1, -1):
            # u_i = t_i · p_i: ∂L/∂Δn_i = κ Im(u_i* G_i); G_{i−1} = H* ⊛ (t_i* G_i)
            grad[i] += self.kappa * xp.sum(xp.imag(xp.conj(kept[i]) * gu), axis=0)
            if i:
                gu = self.bk.ifft2(self.bk.fft2(xp.conj(screens[i // self.substeps]) * gu) * xp.conj(self._h[sl]))
