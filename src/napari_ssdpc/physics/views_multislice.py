"""Multislice (beam-propagation) model of the flat-fielded views, and the gradient of its misfit.

The first-order model of the views (paper Eqs. 2-4: each view's contrast is the sum over slabs of
its defocused weak-object transfer function times the slab's phase) fails on strong objects. This
module predicts the views of a Δn volume without that approximation, with the instrument's scalar
wave optics (the multislice forward models of intensity diffraction tomography: Kamilov et al.,
"Optical tomographic image reconstruction based on beam propagation and sparse regularization",
IEEE TCI 2016; Chowdhury et al., "High-resolution 3D refractive index microscopy of multiple-
scattering samples from intensity images", Optica 2019):

1. Köhler illumination (paper Eq. 2, Abbe's method): plane waves U = exp(i2π w·x) from source points
   w_j over the condenser disk |w| ≤ NA_c/λ on a square lattice of their own spacing h
   (:func:`~napari_ssdpc.physics.apertures.kohler_source`); their intensities add. The points are not
   tied to the grid's frequency lattice: a tilted plane wave is carried as its envelope, which is
   periodic for any w.
2. Multislice through the volume, far side (largest z) first, once per source point: every voxel of
   thickness dz is cut into ``substeps`` slabs of thickness δ, each a phase screen
   t = exp(i2π Δn δ / λ) followed by angular-spectrum propagation over δ in the medium,
   H_δ(u) = exp(i2π δ [η(u + w) − η(w)]) (paper Eq. 6, on the envelope V = U exp(−i2π w·x)). In the
   forward pass the slabs of planes whose Δn is 0 are one step, H_δ^k, and those before the first
   object none (the plane wave's envelope stays 1); the gradient keeps every slab.
3. The field leaving the volume under w_j stands for the q x q sub-points w' of its cell (the
   envelope changes slowly with the tilt; the sharp aperture edges do not): for each sub-point, the
   propagation from the last screen (depth z_exit) to the focal plane, exp(i2π z_exit [η(u) − η(w')]),
   then the objective pupil and each lenslet's sub-aperture A_k = P_obj · circ(|u − u_k| ≤ ρ)
   (paper Eq. 2; docs/conventions.md), evaluated exactly (hard edges) at the absolute frequencies
   u = w' + lattice frequency of an m x m crop of the exit spectrum around u_k − w_j: one coherent
   image g_jqk per sub-point and lenslet, I_k = Σ_jq s_jqk |g_jqk|². The weights s_jqk give each
   lenslet the part of the disk nearest to each sub-point on the same side of that lenslet's edge
   (:func:`~napari_ssdpc.physics.apertures.lenslet_source_weights`), so every view's bright field has
   its exact area. With 0.03 NA between points and q = 3 the views are as close to a converged
   model as with 0.01 NA points alone, 3x cheaper (docs/nonlinear.md).
4. The band-limited I_k (bandwidth 2ρ) is Fourier-interpolated onto the views' pixels, averaged
   over the sensor pixel (a sinc, optional), and divided by the same model's sample-free view I0_k:
   the direct-light background is 1, as in the flat-fielded data
   (:class:`~napari_ssdpc.reconstruction.contrast.ViewContrast`).

The grid is periodic: a square region of interest (ROI) of the views' object grid, sampled
``refine`` times finer; light scattered beyond the ROI re-enters on the other side, so the ROI needs
a margin around the sample. For the pair (source point j, lenslet k) only the part of A_k that lies
inside the grid's band (|u − w| < 1 / (2 dx) per axis) is modelled: light scattered farther from
the illumination is left out (docs/nonlinear.md measures what that costs).

The gradient of the misfit ½ Σ_k ‖W (I_k / I0_k − m_k)‖² with respect to every voxel is
back-propagated by hand through the intensity, the filters, the propagation and the phase screens.
With u_i the field just after screen i and G_i its gradient (∂L/∂u_i* x 2):
∂L/∂Δn_i = (2π δ / λ) Σ_j Im(u_i* G_i), and G_{i−1} = H_δ* ⊛ (t_i* G_i).

Arrays live on the model's :class:`~napari_ssdpc.backend.Backend` (NumPy by default, or CuPy on a
GPU), in complex64 / float32 unless asked otherwise; FFTs are unnormalised forward.
Frequencies are in cycles/µm, lengths in µm.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from napari_ssdpc.backend import Backend, get_backend
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.multislice_source import (
    CropInterpolation,
    even_fast,
    even_planes,
    fits_memory,
    lenslet_crops,
    lit_views,
    model_bytes,
    slab_propagators,
    source_quadrature,
)
from napari_ssdpc.physics.pupil import Pupil
from napari_ssdpc.physics.views_adjoint import ViewsAdjoint
from napari_ssdpc.settings.dpc_optics import DpcOptics
from napari_ssdpc.settings.optics import Optics

__all__ = ["ViewsMultislice"]


class ViewsMultislice(ViewsAdjoint):
    """The flat-fielded views of a Δn volume by multislice, and the gradient of their misfit.

    Parameters
    ----------
    optics : Optics
        Wavelength, medium, objective and condenser NA, sub-aperture radius.
    lenslets : list of Lenslet or array_like, (K, 2)
        The views' lenslets (their ``u``), or the sub-aperture centres u_k (x, y), cycles/µm.
    x_um, y_um : array_like, (w,), (h,)
        The views' object grid (pixel centres, evenly spaced), µm from the optical axis.
    z_um : array_like, (Z,)
        Voxel centres of the volume, µm, increasing and evenly spaced (z > 0: farther from the
        objective).
    roi : (slice, slice), optional
        Rows and columns of the views' grid the model covers (equal lengths;
        :func:`~napari_ssdpc.physics.multislice_source.square_roi`);
        default the whole grid (which must be square).
    refine : int
        Model samples per view pixel along x and y (the model grid is ``refine`` times finer).
    substeps : int
        Multislice slabs per voxel (slab thickness dz / substeps).
    dz_um : float, optional
        Voxel thickness, µm; default the spacing of ``z_um`` (needed for a single plane).
    source_spacing_na : float
        Spacing of the source points in NA units (sin of the angle): the fewer points, the
        cheaper the model and the coarser its partial coherence.
    source_subsamples : int
        q: the field leaving the volume under each source point's tilt stands for q x q sub-points
        of its cell, each of which passes the exit propagation, the pupil and the sub-apertures at
        its own tilt (the sharp edges of the apertures are sampled q times finer than the costly
        multislice; 1: the point alone).
    edge_weights : bool
        Weight the source points per lenslet so that each view's bright-field area is exact
        (:func:`~napari_ssdpc.physics.apertures.lenslet_source_weights`); otherwise every point
        carries its own cell of the disk for every lenslet.
    pixel_integration : bool
        Average the intensity over the sensor pixel (one view pixel), as the camera does.
    chunk : int
        Source points propagated at a time (memory: ``chunk`` x (side·refine)² fields per slab).
    dtype : numpy dtype
        Complex dtype of the fields (complex64; complex128 for gradient checks).
    backend : {'cpu', 'gpu'} or Backend, optional
        Where the fields live and the FFTs run (default the CPU); inputs and outputs live there.
    memory_mb : float
        Largest memory for the fields kept between the forward and the backward pass; beyond it
        the backward pass recomputes them (a third propagation).
    max_bytes : int, optional
        Refuse (:class:`SsdpcError`) a model that would need more memory than this, bytes.
    pupil : Pupil, optional
        The detection pupil; default the optics' (``Pupil.of``). Another front end gives its own
        (an LED array's images: the whole objective pupil, ρ = NA/λ about u_k = 0).
    source : (w, w_sub, wgt), optional
        The source points (S, 2), their sub-points (S, Q, 2) and every sub-point's weight for every
        view (S, Q, K), as :func:`~napari_ssdpc.physics.multislice_source.source_quadrature` gives
        them for the condenser disk (the default); another front end gives its own illumination.
    focus_um : array_like, (K,), optional
        Each view's focal plane, µm (a z-stack's images); default 0 for every view.

    Attributes
    ----------
    shape : tuple of int
        (Z, ny, nx) of the Δn volume the model takes.
    x_um, y_um : ndarray, (nx,), (ny,)
        The model grid, µm.
    view_shape : tuple of int
        (K, h, w) of the views it predicts, on the ROI of the views' grid.
    rows, cols : slice
        The ROI on the views' grid.
    i0 : ndarray, (K,)
        The model's sample-free intensity of every view (the divisor of the flat field).
    n_sources : int
        Source points (multislice propagations).
    n_subsources : int
        Sub-points per source point.
    bytes_needed : int
        Estimated peak memory of a misfit with its gradient, bytes.
    """

    def __init__(
        self,
        optics: Optics | DpcOptics,
        lenslets,
        x_um,
        y_um,
        z_um,
        *,
        roi=None,
        refine: int = 1,
        substeps: int = 1,
        dz_um: float | None = None,
        source_spacing_na: float = 0.04,
        source_subsamples: int = 3,
        edge_weights: bool = True,
        pixel_integration: bool = True,
        chunk: int = 32,
        dtype=np.complex64,
        backend: str | Backend | None = None,
        memory_mb: float = 2048.0,
        max_bytes: int | None = None,
        pupil: Pupil | None = None,
        source=None,
        focus_um=None,
    ):
        self.bk = get_backend(backend)
        self.xp = self.bk.xp
        self.cdtype = np.dtype(dtype)
        self.rdtype = np.finfo(self.cdtype).dtype
        lam, nm = optics.wavelength_um, optics.medium_index
        x, y = np.asarray(x_um, float), np.asarray(y_um, float)
        px = float(x[1] - x[0])
        self.rows: slice = roi[0] if roi is not None else slice(0, len(y))
        self.cols: slice = roi[1] if roi is not None else slice(0, len(x))
        vy, vx = y[self.rows], x[self.cols]
        if len(vy) != len(vx) or len(vx) < 4:
            raise SsdpcError(f"the model's region must be square, got {len(vy)} x {len(vx)} view pixels")
        refine, substeps = int(refine), int(substeps)
        if refine < 1 or substeps < 1:
            raise SsdpcError("refine and substeps must be positive integers")
        z, dz = even_planes(z_um, dz_um)
        self.nv = nv = len(vx)
        self.n = n = nv * refine
        self.dx, self.dz, self.z_um, self.substeps = px / refine, dz, z, substeps
        self.x_um, self.y_um = vx[0] + self.dx * np.arange(n), vy[0] + self.dx * np.arange(n)
        self.shape = (len(z), n, n)
        self.delta = dz / substeps  # slab thickness, µm
        self.kappa = 2 * math.pi * self.delta / lam  # phase per unit Δn of one slab, rad
        z_exit = float(z[0] - dz / 2 + self.delta / 2)  # centre of the slab nearest the objective
        du = 1.0 / (nv * px)
        # --- source points over the condenser disk (paper Eq. 2) on a lattice of step h: the
        # multislice runs once per point; its exit field stands for q x q sub-points of its cell,
        # which the exit propagation, the pupil and the sub-apertures see at their own tilt
        h, q = source_spacing_na / lam, int(source_subsamples)
        if pupil is None or source is None:
            if not isinstance(optics, Optics):
                raise SsdpcError("a front end of other optics gives the model its own pupil and source points")
            pupil = Pupil.of(optics) if pupil is None else pupil
        self.pupil = pupil
        # each lenslet's own sub-aperture: centre u_k, radius ρ_k, defocus d_k (docs/aberrations.md)
        u_k, rho_k, defocus_k = self.pupil.lenslet_arrays(lenslets)
        self.rho = float(rho_k.max())
        if source is None:
            source = source_quadrature(optics, self.pupil, lenslets, h, q, edge_weights)  # type: ignore[arg-type]
        w, w_sub, wgt = source
        q = int(round(math.sqrt(w_sub.shape[1])))
        self.n_sources, self.n_subsources = len(w), q * q
        self.m = m = min(even_fast(int(math.ceil((4 * self.rho + h) / du)) + 4), nv)
        self.chunk = max(1, int(chunk))
        self.memory_mb = float(memory_mb)
        sizes = (self.n_sources, self.n_subsources, len(u_k), n, m, len(z) * substeps, self.chunk)
        self.bytes_needed = model_bytes(*sizes, self.cdtype, self.memory_mb)
        fits_memory(self.bytes_needed, max_bytes, nv * px, len(z))
        # --- propagation through the volume, per source point: exp(i2π δ [η(u + w) − η(w)]) (Eq. 6)
        h_slab = slab_propagators(w, n, self.dx, self.delta, nm, lam)
        # --- lenslet crops: an m x m crop of the exit spectrum around u_k − w_j, for every pair ----
        ex, ey, ux, uy, inx, iny = lenslet_crops(w, w_sub, u_k, du, m, n)
        self.z_exit, self._k2 = z_exit, (nm / lam) ** 2
        eta0 = np.sqrt(self._k2 - np.sum(w_sub**2, axis=-1))  # η(w') of every sub-point, (S, Q)
        # --- intensity: m-crop grid -> the views' pixels (Fourier interpolation, pixel sinc) -----
        self._interpolate = CropInterpolation(m, nv, px * du, pixel_integration, self.bk, self.rdtype)
        self.view_shape = (len(u_k), nv, nv)
        xp_ = self.xp
        self._h = xp_.asarray(h_slab.astype(self.cdtype))
        self._wgt = xp_.asarray(wgt.astype(self.rdtype))
        self._ey, self._ex = xp_.asarray(ey % n), xp_.asarray(ex % n)
        self._ux, self._uy = xp_.asarray(ux.astype(self.rdtype)), xp_.asarray(uy.astype(self.rdtype))
        self._inx, self._iny = xp_.asarray(inx), xp_.asarray(iny)
        self._uk = tuple(xp_.asarray(u_k[:, i].astype(self.rdtype))[:, None, None] for i in range(2))
        self._rho_k = xp_.asarray(rho_k.astype(self.rdtype))[:, None, None]
        self._defocus_k = xp_.asarray(defocus_k.astype(self.rdtype))[:, None, None] if np.any(defocus_k) else None
        self._eta0 = xp_.asarray(eta0.astype(self.rdtype))[..., None, None, None]
        # the exit propagation of every view: from the last screen to its focal plane (z_f = 0 but a z-stack's)
        reach = z_exit - (np.zeros(len(u_k)) if focus_um is None else np.asarray(focus_um, float).reshape(-1))
        self._reach = xp_.asarray(reach.astype(self.rdtype))[:, None, None]
        self._kernels: list | None = None
        i0 = self._interpolate(self._intensity(None)[0])  # sample-free views: constant per lenslet
        self.i0 = lit_views(np.asarray(self.bk.to_host(i0.mean(axis=(1, 2))), float))
        self._i0 = xp_.asarray(self.i0.astype(self.rdtype))[:, None, None]

    def set_pupil_phase(self, zernike, defocus_k) -> None:
        """Give the pupil other phase terms; its apertures, the source points and the direct light
        I0_k (which a phase does not change) stay.

        Parameters
        ----------
        zernike : sequence of float
            The objective's coefficients, Noll j = 1, 2, ..., waves (rms-normalised).
        defocus_k : array_like, (K,)
            Each view's defocus, waves at its sub-aperture's edge.
        """
        c = tuple(float(v) for v in zernike)
        self.pupil = dataclasses.replace(self.pupil, zernike=c if any(c) else ())
        d = np.asarray(defocus_k, float).reshape(-1)
        if d.shape != (self.view_shape[0],):
            raise SsdpcError(f"{d.size} defocus terms for a model of {self.view_shape[0]} views")
        self._defocus_k = self.xp.asarray(d.astype(self.rdtype))[:, None, None] if np.any(d) else None
        self._kernels = None

    # --------------------------------------------------------------------------- forward
    def _screens(self, dn, skip_empty: bool = False):
        """exp(i κ Δn) of every voxel, in propagation order (far side first), (Z, n, n); with
        ``skip_empty`` a list with None for the planes of Δn 0 (a screen of 1: the forward pass
        propagates across them in one step)."""
        xp = self.xp
        dn = xp.asarray(dn, self.rdtype)
        if dn.shape != self.shape:
            raise SsdpcError(f"Δn volume of shape {tuple(dn.shape)}; the model takes {self.shape}")
        if not skip_empty:
            return xp.exp((1j * self.kappa) * dn[::-1]).astype(self.cdtype)
        filled = self.bk.to_host(xp.any(dn[::-1] != 0, axis=(1, 2)))
        return [xp.exp((1j * self.kappa) * d).astype(self.cdtype) if f else None for d, f in zip(dn[::-1], filled)]

    def _chunks(self):
        return [slice(s, min(s + self.chunk, self.n_sources)) for s in range(0, self.n_sources, self.chunk)]

    def _pair_kernel(self, sl):
        """:meth:`_make_kernel`, kept in memory when all of them fit in a quarter of ``memory_mb``."""
        if self._kernels is None:
            size = self.n_sources * self.n_subsources * self.view_shape[0] * self.m**2 * self.cdtype.itemsize
            self._kernels = [self._make_kernel(c) for c in self._chunks()] if size <= self.memory_mb * 2**18 else []
        return self._kernels[sl.start // self.chunk] if self._kernels else self._make_kernel(sl)

    def _make_kernel(self, sl):
        """The exit propagation, the pupil and the sub-aperture on the crops of the source points
        ``sl``: A_k(u) exp(i2π z_exit [η(u) − η(w')]) at u = w' + crop frequency for every sub-point
        w' (paper Eqs. 2 and 6; z_exit − z_f for a view focused at z_f), zero outside the grid's band,
        (s, Q, K, m, m), complex."""
        xp = self.xp
        ux, uy = self._ux[sl][..., None, :], self._uy[sl][..., :, None]
        inside = (
            self.pupil.subaperture(ux, uy, self._uk, xp=xp, rho=self._rho_k)
            & self._iny[sl][..., :, None]
            & self._inx[sl][..., None, :]
        )
        u2 = ux * ux + uy * uy
        phase = (2 * math.pi * self._reach) * (xp.sqrt(xp.maximum(self._k2 - u2, 0)) - self._eta0[sl])
        if self.pupil.zernike or self._defocus_k is not None:  # the objective's and each lenslet's phase
            phase = phase + self.pupil.phase(ux, uy, self._uk, self._rho_k, self._defocus_k, xp)
        return (inside * xp.exp(1j * phase)).astype(self.cdtype)

    def _gather(self, sl):
        """Indices of the crops in a (s, n, n) spectrum: (s, 1, 1, 1), (s, K, m, 1), (s, K, 1, m)."""
        j = self.xp.arange(sl.stop - sl.start)[:, None, None, None]
        return j, self._ey[sl, :, :, None], self._ex[sl, :, None, :]

    def _propagate_chunk(self, screens, sl, keep: bool, empty=None):
        """Lenslet fields g (s, K, m, m) of the source points ``sl``, and the fields after every
        screen (a list, far side first) when ``keep``. Without ``keep``, the slabs of planes that
        ``empty`` marks (Δn 0: the screen is 1) are one propagation step together, H_δ^k."""
        xp, s = self.xp, sl.stop - sl.start
        kept: list = []
        planes = 0 if screens is None else len(screens)
        skip = empty if empty is not None and not keep else [False] * planes
        u, pending = None, 0
        for i in range(planes * self.substeps):
            pending += i > 0
            if skip[i // self.substeps]:
                continue
            screen = screens[i // self.substeps]
            if u is None:  # the plane wave's envelope is 1 up to the first screen: propagation keeps it
                u = xp.broadcast_to(screen, (s, self.n, self.n))
            else:  # pending slabs of medium (Eq. 6), then the screen
                h = self._h[sl] if pending == 1 else self._h[sl] ** pending
                u = self.bk.ifft2(self.bk.fft2(u) * h) * screen
            pending = 0
            if keep:
                kept.append(u)
        if u is None:  # no sample (or no object): the plane wave's envelope is 1
            spec = xp.zeros((s, self.n, self.n), self.cdtype)
            spec[:, 0, 0] = self.n * self.n
        else:
            spec = self.bk.fft2(u) * self._h[sl] ** pending if pending else self.bk.fft2(u)
        g = self.bk.ifft2(spec[self._gather(sl)][:, None] * self._pair_kernel(sl))  # (s, Q, K, m, m)
        return g.astype(self.cdtype, copy=False), kept

    def _intensity(self, screens, keep: bool = False):
        """Σ_j s_jk |g_jk|² on the crop grid (K, m, m), and per chunk what the backward pass needs."""
        acc = self.xp.zeros((self.view_shape[0], self.m, self.m), self.rdtype)
        store = []
        empty = None if keep or screens is None else [sc is None or bool(self.xp.all(sc == 1)) for sc in screens]
        for sl in self._chunks():
            g, kept = self._propagate_chunk(screens, sl, keep, empty)
            acc += self.xp.einsum("jqk,jqkyx->kyx", self._wgt[sl], (g.real**2 + g.imag**2))
            store.append((g, kept) if keep else None)
        return acc, store

    def views(self, dn):
        """The flat-fielded views I_k / I0_k of a Δn volume on the ROI.

        Parameters
        ----------
        dn : ndarray, (Z, ny, nx)
            Δn = n − n_medium of every voxel on the model grid (:attr:`shape`), dimensionless.

        Returns
        -------
        ndarray, (K, h, w), float32 (float64 with complex128 fields)
            1 where a view holds only direct light.
        """
        acc, _ = self._intensity(self._screens(dn, skip_empty=True))
        return self._interpolate(acc) / self._i0

    def crop(self, views):
        """The model's region of views on the whole views' grid.

        Parameters
        ----------
        views : ndarray, (K, H, W)
            Views on the whole object grid (e.g. from ``ViewContrast``).

        Returns
        -------
        ndarray, (K, h, w)
            ``views[:, rows, cols]``.
        """
        return views[:, self.rows, self.cols]
