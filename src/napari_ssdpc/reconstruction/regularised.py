"""3D phase with total variation and physical constraints: the 'tv' method.

The views' contrast c_k obeys the same first-order model as in :mod:`.wotf` (paper Eqs. 2-4):
per lateral frequency u, ĉ_k(u) = Σ_z H_k(u; z)/I0_k · φ̂_z(u). With a handful of views this
leaves a missing cone along z, and the phase WOTFs vanish at u = 0, so the mean of every slice
is not measured at all. A linear (Tikhonov) inverse fills those gaps with zeros: objects come out
weak, long in z and on a haze. Here they are filled with what we know of a sample instead:

    minimise  ½ Σ_k w_k ‖A_k φ − c_k‖² + λ TV(φ)   subject to  φ ∈ C

- TV(φ) = Σ |∂x φ| + |∂y φ| + |∂z φ| with differences per µm (anisotropic total variation: a
  sample is made of regions of nearly constant index with sharp edges);
- C: the sign of Δn against the medium (``denser``: Δn ≥ 0, ``lighter``: Δn ≤ 0), a bound
  |Δn| ≤ Δn_max, and Δn = 0 outside the field stop. The sign and the field stop give the slice
  means back: a slice whose contrast shows nothing holds nothing, instead of an unknown offset.

The solver is ADMM with the splitting of 3D DPC with TV and positivity (Chen, Tian and Waller,
Optica 2016; ADMM after Boyd et al., Found. Trends Mach. Learn. 2011): z₁ = Dφ (the gradients),
z₂ = φ (the constraints). The φ-step is solved exactly: in the 3D Fourier domain DᴴD and I are
diagonal and the data term is K x Z per lateral frequency, so with the Woodbury identity every
frequency costs one K x K product (the inverses are built once, like the Tikhonov operators).

The z grid is padded by a few resolution lengths on each side: a padding plane may hold what the
views see of objects beyond the requested range (it is cropped from the output), so that those
objects do not pile up in the end planes, and the padding decouples the two ends, which the
FFT along z would otherwise join.

λ follows the noise. Beyond |u| = 2ρ (ρ the sub-aperture radius in frequency) no intensity
image of the instrument has any content, so the spectrum of each view out there is its noise; λ
is that noise in the units of the data operator times ``LAMBDA_PER_NOISE`` (docs/method.md).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics import transfer
from napari_ssdpc.physics.design import design
from napari_ssdpc.settings.optics import Optics

__all__ = ["LAMBDA_PER_NOISE", "SIGNS", "TvInversion", "TvReport"]

SIGNS = ("auto", "denser", "lighter", "any")
#: ℓ of the sparsity term μ‖φ‖₁ with μ = λ/ℓ, in units of the axial resolution R_z: without it a
#: constant offset inside the field stop (the unmeasured slice mean) costs only its boundary.
SPARSITY_PER_RZ = 0.5
#: Over-relaxation of the ADMM splits (1: none; 1.5-1.8 is usual).
RELAX = 1.6
#: Warn when the last relative change is above this many times the tolerance.
FAR_FROM_CONVERGED = 5.0
#: Iterations of each sign's probe solve when the sign is 'auto'.
PROBE = 12

#: λ in units of the measured noise times the data operator's strength (docs/method.md).
LAMBDA_PER_NOISE = 1.0
#: ADMM penalty ρ relative to the strongest lateral frequency's data weight Σ_k,z |A|²/Z.
RHO_PER_DATA = 0.5


@dataclass
class TvReport:
    """What the solver did, for the metadata and the convergence plot.

    Attributes
    ----------
    iterations : int
        ADMM iterations run.
    converged : bool
        The relative change fell below the tolerance.
    objective : list of float
        ½‖Aφ − c‖² + λ TV(φ) per iteration (the data term in noise-weighted contrast units).
    relative_change : list of float
        ‖φ_i − φ_{i−1}‖ / ‖φ_i‖ per iteration.
    noise : float
        The views' noise, contrast units (rms per pixel, weighted mean over the views).
    lam : float
        The λ used (absolute, in the units of the objective).
    lam_auto : bool
        λ came from the noise.
    sign : str
        The sign constraint used ('denser', 'lighter' or 'any').
    residual_over_noise : float
        ‖Aφ − c‖² over the band divided by its expectation from the noise alone.
    """

    iterations: int = 0
    converged: bool = False
    objective: list = field(default_factory=list)
    relative_change: list = field(default_factory=list)
    noise: float = float("nan")
    lam: float = float("nan")
    lam_auto: bool = True
    sign: str = "any"
    residual_over_noise: float = float("nan")
    sign_objectives: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Plain numbers for the result's metadata."""
        return {
            "tv_iterations_run": self.iterations,
            "tv_converged": self.converged,
            "tv_objective_final": self.objective[-1] if self.objective else None,
            "tv_noise": self.noise,
            "tv_lambda": self.lam,
            "tv_lambda_auto": self.lam_auto,
            "tv_sign": self.sign,
            "tv_residual_over_noise": self.residual_over_noise,
        }


class TvInversion:
    """Operators of the TV-regularised inversion, built once per optics, lenslets, views and z grid.

    Parameters
    ----------
    optics : Optics
    lenslets : list of Lenslet
        The lit lenslets, in the order of the views.
    shape : tuple of int
        (ny, nx) of a view, px.
    pixel_um : float
        Object-side pixel of the views, µm.
    z_um : array_like, shape (Z,)
        Slab centres, µm (evenly spaced).
    i0 : array_like, shape (K,), optional
        Each view's measured direct light (flat frame); the model's by default. Sets the noise
        weights, as in :class:`~napari_ssdpc.reconstruction.wotf.WotfInversion`.
    mask : ndarray of bool, shape (ny, nx), optional
        The field stop: Δn = 0 outside.
    pad_um : float, optional
        Padding beyond each end of the z range, µm (default: one axial resolution length,
        at least 4 planes).
    progress : callable, optional
        ``progress(done, total, stage)`` while the operators are built.
    """

    def __init__(
        self, optics: Optics, lenslets, shape, pixel_um, z_um, *, i0=None, mask=None, pad_um=None, progress=None
    ):
        z_um = np.atleast_1d(np.asarray(z_um, float))
        self.z_um = z_um
        self.dz = float(z_um[1] - z_um[0]) if len(z_um) > 1 else 1.0
        self.shape = tuple(int(n) for n in shape)
        self.voxel = (self.dz, float(pixel_um), float(pixel_um))
        setup = transfer._LensletSetup(optics, lenslets, shape, float(pixel_um))
        i0_model = setup.i0
        if np.any(i0_model <= 0):
            raise SsdpcError("a view without direct light cannot be inverted; leave dark-field lenslets out")
        i0 = np.asarray(i0_model if i0 is None else i0, float)
        self.w = np.sqrt(i0 / i0.max()).astype(np.float32)  # sqrt of the shot-noise weights
        r_z = float(design(optics)["r_z_ffl_um"])
        self.sparsity_um = SPARSITY_PER_RZ * r_z
        if pad_um is None:
            pad_um = r_z  # one axial resolution length
        self.pad = max(4, int(math.ceil(pad_um / self.dz))) if len(z_um) > 1 else 0
        nz = len(z_um) + 2 * self.pad
        self.nz = nz
        zs = z_um[0] + self.dz * (np.arange(nz) - self.pad)
        self.mask = np.ones(self.shape, bool) if mask is None else np.asarray(mask, bool)
        iy, ix = (transfer._fft_indices(m) % n for m, n in zip(setup.m_out, self.shape))
        self._iy, self._ix = iy[:, None], ix[None, :]
        self.band_shape = tuple(setup.m_out)
        k = len(i0)
        weight = (self.w / i0_model)[:, None, None, None]
        h = np.empty((k, nz) + self.band_shape, np.complex64)  # (K, Z, band): the data operator
        chunk = 16
        for start in range(0, nz, chunk):
            _, hp = setup.band(zs[start : start + chunk])  # (z, K, band)
            h[:, start : start + chunk] = np.swapaxes(hp, 0, 1) * weight
            if progress is not None:
                progress(min(start + chunk, nz), nz, "TV operators")
        self.data_scale = float(np.max(np.sum(np.abs(h) ** 2, axis=(0, 1)))) / nz
        # the same operator on the z frequencies of a unitary DFT along z: Â(kz) = ifft_z(H)
        self.ah = sfft.ifft(h, axis=1, norm="ortho", workers=-1, overwrite_x=True).astype(np.complex64)
        del h
        self.rho = RHO_PER_DATA * self.data_scale
        # eigenvalues of DᴴD (forward differences per µm, periodic) on the padded 3D grid
        dzz = (2 * np.sin(np.pi * sfft.fftfreq(nz))) ** 2 / self.dz**2
        dyy = (2 * np.sin(np.pi * sfft.fftfreq(self.shape[0]))) ** 2 / self.voxel[1] ** 2
        dxx = (2 * np.sin(np.pi * sfft.fftfreq(self.shape[1]))) ** 2 / self.voxel[2] ** 2
        self._dtd = (dzz[:, None, None] + dyy[None, :, None] + dxx[None, None, :]).astype(np.float32)
        self._build_inverse()

    def _build_inverse(self):
        """b = ρ(1 + DᴴD) and, per band frequency, G⁻¹ = (I + Â b⁻¹ Âᴴ)⁻¹ (K x K)."""
        self.b = (self.rho * (1.0 + self._dtd)).astype(np.float32)  # (kz, ny, nx)
        binv_band = 1.0 / self.b[:, self._iy, self._ix]  # (kz, band)
        g = np.einsum("kzyx,zyx,lzyx->yxkl", self.ah, binv_band, np.conj(self.ah), optimize=True)
        g += np.eye(g.shape[-1], dtype=g.dtype)
        self.ginv = np.linalg.inv(g).astype(np.complex64)  # (band, K, K)

    # ------------------------------------------------------------------ pieces
    def spectra(self, contrast) -> np.ndarray:
        """Weighted contrast spectra (K, ny, nx), unitary 2D FFT."""
        c = np.asarray(contrast, np.float32) * self.w[:, None, None]
        return sfft.fft2(c, norm="ortho", workers=-1)

    def noise(self, spectra) -> float:
        """The views' noise (rms per pixel, weighted contrast) from their spectra beyond the band.

        Nothing the instrument images lies beyond |u| = 2ρ; the median of |ĉ|² out there is
        robust against the few frequencies the field-stop edge leaks.
        """
        outside = np.ones(self.shape, bool)
        outside[self._iy, self._ix] = False
        if outside.sum() < 16:
            return float("nan")
        power = np.abs(spectra[:, outside]) ** 2
        frac = float(self.mask.mean())  # noise lives only inside the field stop
        return float(np.sqrt(np.median(power) / math.log(2) / max(frac, 1e-6)))

    def forward_band(self, phi_hat) -> np.ndarray:
        """Â φ̂ on the band: (K, band) from φ̂ (kz, ny, nx)."""
        return np.einsum("kzyx,zyx->kyx", self.ah, phi_hat[:, self._iy, self._ix], optimize=True)

    def _solve(self, rhs_hat) -> np.ndarray:
        """(ÂᴴÂ + b)⁻¹ r̂ by Woodbury: r̂/b − b⁻¹Âᴴ G⁻¹ Â (r̂/b)."""
        x = rhs_hat / self.b
        xb = x[:, self._iy, self._ix]
        t = np.einsum("kzyx,zyx->kyx", self.ah, xb, optimize=True)
        t = np.einsum("yxkl,lyx->kyx", self.ginv, t, optimize=True)
        corr = np.einsum("kzyx,kyx->zyx", np.conj(self.ah), t, optimize=True) / self.b[:, self._iy, self._ix]
        x[:, self._iy, self._ix] = xb - corr
        return x

    def _grad(self, phi):
        """Forward differences per µm (periodic): (3, Z, ny, nx)."""
        return np.stack([(np.roll(phi, -1, axis=a) - phi) / self.voxel[a] for a in range(3)])

    def _grad_adj(self, g):
        """Dᴴ of :meth:`_grad`."""
        return sum((np.roll(g[a], 1, axis=a) - g[a]) / self.voxel[a] for a in range(3))

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
        progress=None,
        should_stop=None,
        quiet: bool = False,
    ) -> tuple[np.ndarray, TvReport]:
        """Phase per slab (Z, ny, nx), rad, and the solver's report.

        Parameters
        ----------
        contrast : ndarray, shape (K, ny, nx)
            I_k / I0_k − 1 of each view (0 outside the field stop).
        warm : ndarray, shape (Z, ny, nx), optional
            Starting point (the Tikhonov phase).
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
        progress : callable, optional
            ``progress(done, total, 'TV')`` per iteration.
        should_stop : callable, optional
            Checked every iteration; True stops with the current estimate (report.converged False).
        quiet : bool
            No warning when the iteration limit is reached (the sign probes).

        Returns
        -------
        phi : ndarray, float32, shape (Z, ny, nx)
        report : TvReport
        """
        if sign not in SIGNS:
            raise SsdpcError(f"sign '{sign}': use one of {', '.join(SIGNS)}")
        if sign == "auto":
            # the sign the data support: a short solve with each, the lower objective wins
            kw = dict(warm=warm, phi_max=phi_max, lam=lam, iterations=PROBE, tol=0.0, quiet=True)
            probes = {s: self.phase(contrast, sign=s, **kw) for s in ("denser", "lighter")}
            best = min(probes, key=lambda s: probes[s][1].objective[-1])
            other = "lighter" if best == "denser" else "denser"
            phi, report = self.phase(
                contrast,
                warm=probes[best][0],
                sign=best,
                phi_max=phi_max,
                lam=lam,
                iterations=max(iterations - PROBE, 1),
                tol=tol,
                progress=progress,
                should_stop=should_stop,
            )
            report.sign_objectives = {s: probes[s][1].objective[-1] for s in probes}
            report.objective = probes[best][1].objective + report.objective
            report.relative_change = probes[best][1].relative_change + report.relative_change
            report.iterations += PROBE  # the chosen sign's path; the other probe ran PROBE more
            report.sign = f"auto: {best} (objective {report.sign_objectives[best]:.4g} vs {other} "
            report.sign += f"{report.sign_objectives[other]:.4g})"
            return phi, report
        spec = self.spectra(contrast)
        sigma = self.noise(spec)
        band = spec[:, self._iy, self._ix]
        rhs0 = np.zeros((self.nz,) + self.shape, np.complex64)
        rhs0[:, self._iy, self._ix] = np.einsum("kzyx,kyx->zyx", np.conj(self.ah), band, optimize=True)
        scale = sigma * math.sqrt(self.data_scale) if math.isfinite(sigma) and sigma > 0 else 1e-3
        report = TvReport(noise=sigma, lam_auto=lam is None, sign=sign)
        lam_abs = LAMBDA_PER_NOISE * scale * (1.0 if lam is None else float(lam))
        report.lam = lam_abs
        # the variables live on the padded grid
        p = self.pad
        zsl = slice(p, p + len(self.z_um))
        phi = np.zeros((self.nz,) + self.shape, np.float32)
        if warm is not None:
            phi[zsl] = warm
        z1 = self._grad(phi)
        u1 = np.zeros_like(z1)
        z2 = self._project(phi, sign, phi_max)
        u2 = np.zeros_like(phi)
        thresh = lam_abs / self.rho * float(np.prod(self.voxel))
        l1 = thresh / self.sparsity_um  # μ = λ / ℓ: the medium is Δn = 0 where the data need nothing
        for it in range(iterations):
            if should_stop is not None and should_stop():
                break
            r = self._grad_adj(z1 - u1) + (z2 - u2)
            rhs = rhs0 + sfft.fftn(r, norm="ortho", workers=-1) * self.rho
            phi_hat = self._solve(rhs)
            new = sfft.ifftn(phi_hat, norm="ortho", workers=-1).real.astype(np.float32)
            change = float(np.linalg.norm(new - phi)) / max(float(np.linalg.norm(new)), 1e-12)
            phi = new
            g = self._grad(phi)
            data = float(np.sum(np.abs(self.forward_band(phi_hat) - band) ** 2))
            penalty = lam_abs * (float(np.sum(np.abs(g))) + float(np.sum(np.abs(phi))) / self.sparsity_um)
            report.objective.append(0.5 * data + penalty * float(np.prod(self.voxel)))
            # over-relaxed ADMM (Boyd et al. 2011, §3.4.3): converges in fewer iterations
            v = RELAX * g + (1 - RELAX) * z1 + u1
            z1 = _shrink(v, thresh)
            u1 = v - z1
            w = RELAX * phi + (1 - RELAX) * z2
            z2 = self._project(_shrink(w + u2, l1), sign, phi_max)
            u2 = u2 + w - z2
            report.relative_change.append(change)
            report.iterations = it + 1
            if progress is not None:
                progress(it + 1, iterations, "TV")
            if change < tol and it > 2:
                report.converged = True
                break
        out = self._project(phi, sign, phi_max)  # the feasible point nearest the last iterate
        res = self._residual(out, band)
        expected = self._noise_power(sigma, band.shape)
        report.residual_over_noise = res / expected if expected > 0 else float("nan")
        last = report.relative_change[-1] if report.relative_change else float("inf")
        # the limit ends most solves a little short of ``tol`` (0.5% change per iteration after 60):
        # warn only when the iterate is still moving fast
        if not quiet and last > FAR_FROM_CONVERGED * tol and (should_stop is None or not should_stop()):
            warnings.warn(
                f"the TV solve did not converge in {report.iterations} iterations (last relative change "
                f"{last:.2g} > {FAR_FROM_CONVERGED * tol:g}); "
                "raise tv_iterations",
                SsdpcWarning,
                stacklevel=2,
            )
        return out[zsl], report

    def _project(self, phi, sign, phi_max):
        lo = 0.0 if sign == "denser" else -phi_max
        hi = 0.0 if sign == "lighter" else phi_max
        return np.clip(phi, lo, hi) * self.mask

    def _residual(self, phi, band) -> float:
        phi_hat = sfft.fftn(phi, norm="ortho", workers=-1)
        return float(np.sum(np.abs(self.forward_band(phi_hat) - band) ** 2))

    def _noise_power(self, sigma, band_shape) -> float:
        return float(sigma**2 * self.mask.mean() * np.prod(band_shape))


def _shrink(v, t):
    """Soft threshold: the proximal step of t‖·‖₁."""
    return np.sign(v) * np.maximum(np.abs(v) - t, 0)
