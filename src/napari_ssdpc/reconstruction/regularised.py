"""3D phase with total variation and physical constraints: the 'tv' method.

The views' contrast c_k obeys the first-order model of :mod:`.forward` (paper Eqs. 2-4):
per lateral frequency u, ĉ_k(u) = Σ_z H_k(u; z)/I0_k · φ̂_z(u). With a handful of views this
leaves a missing cone along z, and the phase WOTFs vanish at u = 0, so the mean of every slice
is not measured at all. A linear (Tikhonov) inverse fills those gaps with zeros: objects come out
weak, long in z and on a haze. Here they are filled with what we know of a sample instead:

    minimise  ½ Σ_k w_k ‖A_k φ − c_k‖² + λ TV(φ) + (λ/ℓ) ‖φ‖₁   subject to  φ ∈ C

- TV(φ) = Σ |∂x φ| + |∂y φ| + |∂z φ| with differences per µm (anisotropic total variation: a
  sample is made of regions of nearly constant index with sharp edges);
- ‖φ‖₁ with the length ℓ = ``SPARSITY_PER_RZ`` x R_z: the medium is Δn = 0 wherever the data do
  not need more (the slice means are not measured);
- C: the sign of Δn against the medium (``denser``: Δn ≥ 0, ``lighter``: Δn ≤ 0), a bound
  |Δn| ≤ Δn_max, and Δn = 0 outside the field stop. The sign and the field stop give the slice
  means back: a slice whose contrast shows nothing holds nothing, instead of an unknown offset.

The solver is ADMM with the splitting of 3D DPC with TV and positivity (Chen, Tian and Waller,
Optica 2016; ADMM after Boyd et al., Found. Trends Mach. Learn. 2011): z₁ = Dφ (the gradients),
z₂ = φ (the constraints). The φ-step is solved exactly: in the 3D Fourier domain DᴴD and I are
diagonal and the data term is K x Z per lateral frequency, so with the Woodbury identity every
frequency costs one K x K product (the inverses are built once, like the Tikhonov operators).
Because φ is real, everything runs on the half spectrum of a real 3D FFT, and the products are
batched over the band's frequencies (``@`` on contiguous (P, K, Z) arrays). Every array lives on
the model's device (:mod:`napari_ssdpc.backend`: NumPy on the CPU, CuPy on a GPU); only the views come in and
the phase goes out.

The z grid is padded by about one axial resolution length on each side (:func:`padded_planes`).

λ follows the noise. Beyond |u| = 2ρ (ρ the sub-aperture radius in frequency) no intensity
image of the instrument has any content, so the spectrum of each view out there is its noise; λ
is that noise in the units of the data operator times ``LAMBDA_PER_NOISE`` (docs/method.md).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import in_threads
from napari_ssdpc.blas import one_blas_thread
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.reconstruction.forward import ViewModel, apply
from napari_ssdpc.reconstruction.proximal import bounds, constraint_step, gradient_step
from napari_ssdpc.reconstruction.sign_probes import solve_with_auto_sign
from napari_ssdpc.reconstruction.tv_report import TvReport
from napari_ssdpc.settings.reconstruction import SIGNS

__all__ = ["LAMBDA_PER_NOISE", "TvInversion", "TvState"]

#: ℓ of the sparsity term μ‖φ‖₁ with μ = λ/ℓ, in units of the axial resolution R_z: without it a
#: constant offset inside the field stop (the unmeasured slice mean) costs only its boundary.
#: Measured (docs/validation.md): 0.5 R_z leaves a haze of noise that the sign constraint keeps
#: (Σ Δn over the field 3 x a weak bead's); 0.1 R_z cuts it 4-fold and keeps the objects within
#: 4%; 0.02 R_z starts to eat them (−17%).
SPARSITY_PER_RZ = 0.1
#: Warn when the last relative change is above this many times the tolerance.
FAR_FROM_CONVERGED = 5.0

#: λ in units of the measured noise times the data operator's strength (docs/method.md).
LAMBDA_PER_NOISE = 1.0
#: ADMM penalty ρ relative to the strongest lateral frequency's data weight Σ_k,z |A|²/Z.
RHO_PER_DATA = 0.5


@dataclass
class TvState:
    """Where an ADMM solve ended: the start of the next frame of a series.

    The splits' variables carry what the solve learned of the sample (its edges in z₁, the
    support and sign in z₂, the multipliers u₁ and u₂); a frame that differs a little from the
    previous one starts next to its own solution and needs a fraction of the iterations.

    Attributes
    ----------
    phi : array, float32, (Z, ny, nx)
        Phase on the padded z grid (the model's planes), rad, on the model's device.
    z1, u1 : array, float32, (3, Z, ny, nx)
        Gradient split and its scaled multiplier.
    z2, u2 : array, float32, (Z, ny, nx)
        Constraint split and its scaled multiplier.
    sign : str
        The sign constraint the solve used ('denser', 'lighter' or 'any'; 'auto' resolved).
    """

    phi: Any
    z1: Any
    u1: Any
    z2: Any
    u2: Any
    sign: str


class TvInversion:
    """The TV-regularised inversion of a :class:`~napari_ssdpc.reconstruction.forward.ViewModel`.

    Parameters
    ----------
    model : ViewModel
        The views' model on the padded z grid of :func:`padded_planes`.
    planes : slice
        The requested planes within the model's (the output).
    r_z_um : float
        Axial resolution, µm: sets the sparsity length (``SPARSITY_PER_RZ``).
    mask : ndarray of bool, shape (ny, nx), optional
        The field stop: Δn = 0 outside.
    """

    def __init__(self, model: ViewModel, planes: slice, r_z_um: float, *, mask=None):
        self.model = model
        z = model.z_um
        self.nz = nz = len(z)
        self.planes = planes
        self.z_um = z[planes]
        self.dz = float(z[1] - z[0]) if nz > 1 else 1.0
        self.shape = model.shape
        self.voxel = (self.dz, model.pixel_um, model.pixel_um)
        self.sparsity_um = SPARSITY_PER_RZ * float(r_z_um)
        self.mask = np.ones(self.shape, bool) if mask is None else np.asarray(mask, bool)
        self.bk = bk = model.bk
        self.xp = xp = bk.xp
        self._mask = bk.asarray(self.mask)
        # the model on the z frequencies of a unitary DFT along z: Â(kz) = ifft_z(A)
        self.ah = bk.ifft(model.a, axis=2, norm="ortho").astype(np.complex64)  # (P, K, Z)
        self.ah_h = xp.ascontiguousarray(xp.conj(self.ah).transpose(0, 2, 1))  # (P, Z, K)
        self.data_scale = float(xp.max(xp.sum(xp.abs(model.a) ** 2, axis=(1, 2)))) / nz
        self.rho = RHO_PER_DATA * self.data_scale
        # eigenvalues of DᴴD (forward differences per µm, periodic) on the half spectrum
        ny, nx = self.shape
        dzz = (2 * np.sin(np.pi * sfft.fftfreq(nz))) ** 2 / self.voxel[0] ** 2
        dyy = (2 * np.sin(np.pi * sfft.fftfreq(ny))) ** 2 / self.voxel[1] ** 2
        dxx = (2 * np.sin(np.pi * np.arange(nx // 2 + 1) / nx)) ** 2 / self.voxel[2] ** 2
        dtd = dzz[:, None, None] + dyy[None, :, None] + dxx[None, None, :]
        self.b = bk.asarray((self.rho * (1.0 + dtd)).astype(np.float32))  # (kz, ny, nx//2+1)
        self.binv_band = xp.ascontiguousarray(1.0 / model.take(self.b))  # (P, kz)
        # per band frequency G⁻¹ = (I + Â b⁻¹ Âᴴ)⁻¹ (K x K), for the Woodbury identity
        with one_blas_thread:  # many small products and inverses (see napari_ssdpc.blas)
            g = (self.ah * self.binv_band[:, None, :]) @ self.ah_h
            g += xp.eye(model.n_views, dtype=g.dtype)
            self.ginv = xp.linalg.inv(g).astype(np.complex64)
        outside = np.ones(dtd.shape[1:], bool)
        model.band.put(outside, np.zeros(model.band.box_shape, bool))
        self._n_outside = int(outside.sum())
        self._outside = bk.asarray(outside)

    # ------------------------------------------------------------------ pieces
    def noise(self, contrast) -> float:
        """The views' noise (rms per pixel, weighted contrast) from their spectra beyond the band.

        Nothing the instrument images lies beyond |u| = 2ρ; the median of |ĉ|² out there is
        robust against the few frequencies the field-stop edge leaks.

        Parameters
        ----------
        contrast : ndarray, float32, (K, ny, nx)

        Returns
        -------
        float
        """
        return self._noise(self.model.full_spectra(contrast))

    def _noise(self, spec) -> float:
        if self._n_outside < 8:
            return float("nan")
        power = self.xp.abs(spec[:, self._outside]) ** 2
        frac = float(self.mask.mean())  # noise lives only inside the field stop
        return math.sqrt(float(self.xp.median(power)) / math.log(2) / max(frac, 1e-6))

    def _fft(self, phi):
        return self.bk.rfftn(phi, norm="ortho")

    def _ifft(self, phi_hat):
        return self.bk.irfftn(phi_hat, s=(self.nz,) + self.shape, norm="ortho")

    def _solve(self, rhs_hat):
        """(ÂᴴÂ + b)⁻¹ r̂ by Woodbury, r̂/b − b⁻¹Âᴴ G⁻¹ Â (r̂/b), and Â of the solution.

        Â of the solution is G⁻¹ Â (r̂/b): Â(x − b⁻¹ÂᴴG⁻¹Âx) = (I − (G − I)G⁻¹)Âx.
        """
        x = rhs_hat / self.b
        model = self.model
        xb = model.take(x)  # (P, kz)
        fwd = apply(self.ginv, apply(self.ah, xb))  # (P, K)
        corr = apply(self.ah_h, fwd) * self.binv_band
        model.band.put(x, (xb - corr).T.reshape((self.nz,) + model.band.box_shape))
        return x, fwd

    def _data(self, fwd, band) -> float:
        """‖Âφ̂ − ĉ‖² over the whole spectrum, from the half band."""
        return float(self.xp.sum(self.model.multiplicity[:, None] * abs(fwd - band) ** 2))

    def _grad(self, phi, out=None):
        """Forward differences per µm (periodic): (3, Z, ny, nx)."""
        xp = self.xp
        out = xp.empty((3,) + phi.shape, np.float32) if out is None else out
        for a, h in enumerate(self.voxel):
            p, g = xp.moveaxis(phi, a, 0), xp.moveaxis(out[a], a, 0)
            xp.subtract(p[1:], p[:-1], out=g[:-1])
            xp.subtract(p[:1], p[-1:], out=g[-1:])
            g *= np.float32(1 / h)
        return out

    def _grad_adj(self, g):
        """Dᴴ of :meth:`_grad`: Σ_a (g_a[i−1] − g_a[i]) / h_a."""
        xp = self.xp
        out = xp.zeros(g.shape[1:], np.float32)
        tmp = xp.empty_like(out)
        for a, h in enumerate(self.voxel):
            ga, t = xp.moveaxis(g[a], a, 0), xp.moveaxis(tmp, a, 0)
            xp.subtract(ga[:-1], ga[1:], out=t[1:])
            xp.subtract(ga[-1:], ga[:1], out=t[:1])
            t *= np.float32(1 / h)
            out += tmp
        return out

    # ------------------------------------------------------------------ solve
    def phase(
        self,
        contrast,
        *,
        warm=None,
        sign: str = "any",
        phi_max: float = np.inf,
        lam: float | None = None,
        iterations: int = 60,
        tol: float = 2e-3,
        temporal_weight: float = 0.0,
        progress=None,
        should_stop=None,
        quiet: bool = False,
    ) -> tuple[np.ndarray, TvReport]:
        """Phase per slab (Z, ny, nx), rad, and the solver's report.

        Parameters
        ----------
        contrast : ndarray, shape (K, ny, nx)
            I_k / I0_k − 1 of each view (0 outside the field stop).
        warm : ndarray, shape (Z, ny, nx), or TvState, optional
            Starting point: a phase on the output planes (the Tikhonov phase), or where the
            previous frame's solve ended (its variables and its sign: 'auto' probes no more).
        sign : {'auto', 'denser', 'lighter', 'any'}
            φ ≥ 0, φ ≤ 0 or either; 'auto': the sign whose short solve explains the data
            better (lower objective after a few iterations with each).
        phi_max : float
            Bound on |φ| per slab, rad (from Δn_max).
        lam : float, optional
            λ in units of the noise-based default (1 = the default); None: automatic.
        iterations : int
            Most ADMM iterations.
        tol : float
            Stop when the relative change of φ falls below this.
        temporal_weight : float
            γ/μ of the temporal prior γ‖φ − φ_prev‖₁, relative to the sparsity weight μ; used only
            with a ``warm`` TvState (φ_prev: its constraint split z₂, the previous frame's feasible
            phase). 0: none.
        progress : callable, optional
            ``progress(done, total, 'TV')`` per iteration.
        should_stop : callable, optional
            Checked every iteration; True stops with the current estimate (report.converged False).
        quiet : bool
            No warning when the iteration limit is reached (the sign probes).

        Returns
        -------
        phi : numpy.ndarray, float32, shape (Z, ny, nx)
            On the host, whatever the model's device.
        report : TvReport
            With the end state (``report.state``, a :class:`TvState`).
        """
        if sign not in SIGNS:
            raise SsdpcError(f"sign '{sign}': use one of {', '.join(SIGNS)}")
        if isinstance(warm, TvState) and sign == "auto":
            sign = warm.sign
        if sign == "auto":
            return solve_with_auto_sign(self, contrast, warm, phi_max, lam, iterations, tol, progress, should_stop)
        spec = self.model.full_spectra(contrast)
        sigma = self._noise(spec)
        band = self.model.take(spec)  # (P, K)
        rhs0 = self.model.put(apply(self.ah_h, band), self.nz)
        scale = sigma * math.sqrt(self.data_scale) if math.isfinite(sigma) and sigma > 0 else 1e-3
        report = TvReport(noise=sigma, lam_auto=lam is None, sign=sign, warm=isinstance(warm, TvState))
        if temporal_weight < 0:
            raise SsdpcError(f"temporal_weight {temporal_weight:g}: use a weight >= 0 (0: no temporal prior)")
        prior = None
        if isinstance(warm, TvState) and temporal_weight > 0:
            prior = self.xp.array(warm.z2, copy=True)  # the previous frame's feasible phase
            report.temporal_weight = float(temporal_weight)
        lam_abs = LAMBDA_PER_NOISE * scale * (1.0 if lam is None else float(lam))
        report.lam = lam_abs
        cell = float(np.prod(self.voxel))
        # the variables live on the padded grid, on the device
        xp = self.xp
        if isinstance(warm, TvState):
            phi, z1, u1, z2, u2 = (xp.array(a, copy=True) for a in (warm.phi, warm.z1, warm.u1, warm.z2, warm.u2))
            xp.clip(z2, *bounds(sign, phi_max), out=z2)
        else:
            phi = xp.zeros((self.nz,) + self.shape, np.float32)
            if warm is not None:
                phi[self.planes] = self.bk.asarray(warm, np.float32)
            z1 = self._grad(phi)
            u1 = xp.zeros_like(z1)
            z2 = self._project(phi, sign, phi_max)
            u2 = xp.zeros_like(phi)
        g = xp.empty_like(z1)
        thresh = np.float32(lam_abs / self.rho * cell)
        l1 = thresh / np.float32(self.sparsity_um)  # μ = λ / ℓ: the medium is Δn = 0 where the data need nothing
        for it in range(iterations):
            if should_stop is not None and should_stop():
                break
            xp.subtract(z1, u1, out=g)
            r = self._grad_adj(g)
            r += z2
            r -= u2
            rhs = self._fft(r)
            rhs *= self.rho
            rhs += rhs0
            phi_hat, fwd = self._solve(rhs)
            new = self._ifft(phi_hat)
            change = float(xp.linalg.norm(new - phi)) / max(float(xp.linalg.norm(new)), 1e-12)
            phi = new
            self._grad(phi, out=g)
            tv = gradient_step(g, z1, u1, thresh, self._parts, xp)
            l1_sum = float(abs(phi).sum())
            if prior is not None:
                l1_sum += temporal_weight * float(abs(phi - prior).sum())
            penalty = lam_abs * (tv + l1_sum / self.sparsity_um)
            report.objective.append(0.5 * self._data(fwd, band) + penalty * cell)
            constraint_step(
                phi,
                z2,
                u2,
                l1,
                bounds(sign, phi_max),
                g[0],
                self._mask,
                self._parts,
                xp,
                prior=prior,
                gamma=l1 * np.float32(temporal_weight),
            )
            report.relative_change.append(change)
            report.iterations = it + 1
            if progress is not None:
                progress(it + 1, iterations, "TV")
            if change < tol and it > 2:
                report.converged = True
                break
        out = self._project(phi, sign, phi_max)  # the feasible point nearest the last iterate
        report.state = TvState(phi, z1, u1, z2, u2, sign)
        res = self._data(apply(self.ah, self.model.take(self._fft(out))), band)
        expected = float(sigma**2 * self.mask.mean() * self.model.multiplicity.sum())
        report.residual_over_noise = res / expected if expected > 0 else float("nan")
        last = report.relative_change[-1] if report.relative_change else float("inf")
        # the limit ends most solves a little short of ``tol`` (0.5% change per iteration after 60):
        # warn only when the iterate is still moving fast
        if not quiet and last > FAR_FROM_CONVERGED * tol and (should_stop is None or not should_stop()):
            warnings.warn(
                f"the TV solve did not converge in {report.iterations} iterations (last relative change "
                f"{last:.2g} > {FAR_FROM_CONVERGED * tol:g}); "
                + (
                    "a frame that starts from the previous one: raise tv.warm_iterations (--tv-warm-iterations)"
                    if isinstance(warm, TvState)
                    else "raise tv_iterations"
                ),
                SsdpcWarning,
                stacklevel=2,
            )
        return self.bk.to_host(out[self.planes]), report

    def _project(self, phi, sign, phi_max):
        return self.xp.clip(phi, *bounds(sign, phi_max)) * self._mask

    def _parts(self, part) -> float:
        """Σ ``part(planes)``: one part per core on the CPU (NumPy releases the GIL), the whole
        volume at once on a GPU."""
        return part(slice(None)) if self.bk.is_gpu else sum(in_threads(part, self.nz))
