"""The ssDPC reconstruction: one raw frame in, a 3D refractive-index volume out.

Per frame (paper §2 and §3.2, docs/conventions.md):
1. dark subtraction, EI extraction with the calibration, flat-fielding view by view
   (each view's direct-light background becomes 1), clipping at zero;
2. four directional light fields (Eq. 5): the views of the up, down, left and right halves,
   each deconvolved by multi-view Richardson–Lucy with the wave-optics PSF (Eq. 6) into an
   intensity stack I_κ(z);
3. DPC stacks (Eq. 1) with every slice normalised by the z-summed background of the pair, so
   that a slice holds only its own contrast; absorption from the sum of the four stacks.
4. Phase, by one of three methods:
   - 'tv' (default): the views' defocused weak-object transfer functions inverted with total
     variation, the sign of Δn, a bound and the field stop (:mod:`.regularised`), started from
     the Tikhonov solution;
   - 'wotf': 3D Tikhonov over all flat-fielded views with the same operators (:mod:`.wotf`):
     linear and fastest;
   - 'rl' (the paper's route): Tikhonov phase per slice (Eq. 7) from the DPC stacks with the
     in-focus DPC transfer function of the chosen model.
   docs/validation.md compares them. Then Δn = λφ/(2π dz) and n = n_medium + Δn.

Lenslets that receive no direct light at this condenser NA (dark field) carry no first-order
phase signal (docs/conventions.md) and are left out of the halves.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.calibration.calibrate import Calibration, extract_views
from napari_ssdpc.calibration.saturation import warn_saturation
from napari_ssdpc.errors import Cancelled, SsdpcError, SsdpcWarning
from napari_ssdpc.physics import dpc_transfer, transfer
from napari_ssdpc.physics.design import design
from napari_ssdpc.physics.psf import LensletPSF
from napari_ssdpc.reconstruction.backend import get_backend
from napari_ssdpc.reconstruction.deconvolution import Band, MultiViewRL
from napari_ssdpc.reconstruction.dpc import dpc_image, phase_to_delta_n, refractive_index, tikhonov_phase
from napari_ssdpc.reconstruction.forward import ViewModel
from napari_ssdpc.reconstruction.regularised import TvInversion, padded_planes
from napari_ssdpc.reconstruction.wotf import WotfInversion
from napari_ssdpc.settings.lenslets import HALVES, PAIRS
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import DEFAULT_ALPHA, PHASE_METHODS, TRANSFER_MODELS, ReconstructionSettings

__all__ = ["Cancelled", "Reconstructor", "Result", "estimate_dark", "z_grid"]


def z_grid(z_min_um: float, z_max_um: float, dz_um: float) -> np.ndarray:
    """Planes from z_min to z_max (inclusive) every dz µm.

    Parameters
    ----------
    z_min_um, z_max_um : float
        First and last plane, µm from the focal plane.
    dz_um : float
        Spacing, µm.

    Returns
    -------
    ndarray, float64, (Z,)
    """
    if not dz_um > 0:
        raise SsdpcError(f"dz must be > 0 µm, got {dz_um}")
    if z_max_um < z_min_um:
        raise SsdpcError(f"z range is empty: z_max {z_max_um} < z_min {z_min_um}; give --z ZMIN ZMAX with ZMIN <= ZMAX")
    n = int(math.floor((z_max_um - z_min_um) / dz_um + 1e-6)) + 1
    return (z_min_um + dz_um * np.arange(n)).astype(np.float64)


def estimate_dark(frame, calibration: Calibration) -> float:
    """Dark offset: median of the pixels farther than 1.2 EI radii from every lenslet centre.

    Parameters
    ----------
    frame : ndarray, (H, W)
        Camera units.
    calibration : Calibration

    Returns
    -------
    float
        Camera units.
    """
    img = np.asarray(frame, np.float32)
    step = 8  # a sparse sample is plenty for a median
    yy, xx = np.mgrid[0 : img.shape[0] : step, 0 : img.shape[1] : step]
    far = np.ones(yy.shape, bool)
    r2 = (1.2 * calibration.ei_radius_px) ** 2
    for cx, cy in calibration.centres_px:
        far &= (xx - cx) ** 2 + (yy - cy) ** 2 > r2
    if far.sum() < 100:
        raise SsdpcError("no dark pixels outside the elemental images to estimate the dark offset; pass dark=VALUE")
    return float(np.median(img[yy[far], xx[far]]))


@dataclass
class Result:
    """Reconstruction of one frame. Arrays are (z, y, x) with coordinates in µm."""

    ri: np.ndarray
    delta_n: np.ndarray
    phase: np.ndarray
    absorption: np.ndarray | None
    dpc: dict
    stacks: dict
    z_um: np.ndarray
    y_um: np.ndarray
    x_um: np.ndarray
    convergence: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)

    @property
    def voxel_um(self) -> tuple[float, float, float]:
        """(dz, dy, dx) in µm; dz of a single plane is the slab thickness it was made with."""
        dz = float(self.z_um[1] - self.z_um[0]) if len(self.z_um) > 1 else float(self.settings.get("dz_um", 1.0))
        return dz, float(self.y_um[1] - self.y_um[0]), float(self.x_um[1] - self.x_um[0])

    @property
    def projected_phase(self) -> np.ndarray:
        """(y, x) phase summed over the slabs, rad: what a 2D quantitative phase image shows."""
        return np.asarray(np.sum(self.phase, axis=0, dtype=np.float64), np.float32)

    @property
    def opd_nm(self) -> np.ndarray:
        """(y, x) optical path difference Σ_z Δn dz, nm."""
        return np.asarray(1e3 * self.voxel_um[0] * np.sum(self.delta_n, axis=0, dtype=np.float64), np.float32)

    @property
    def dry_mass(self) -> np.ndarray:
        """(y, x) dry-mass surface density OPD / α, pg/µm² (α: the specific refraction increment)."""
        alpha = float(self.settings.get("refraction_increment_um3_pg", 0.19))
        return (1e-3 * self.opd_nm / alpha).astype(np.float32)


class Reconstructor:
    """Everything computed once per optics, calibration and z range: the lenslet selection, the
    flat-field, the PSF operators of each half and the DPC transfer functions."""

    def __init__(
        self,
        optics: Optics,
        calibration: Calibration,
        settings: ReconstructionSettings | None = None,
        *,
        z=None,
        dz=None,
        iterations=None,
        alpha=None,
        model=None,
        method=None,
        flat=None,
        dark=None,
        stacks: bool = True,
        min_light: float = 0.05,
        progress=None,
        device=None,
    ):
        rec = (settings or ReconstructionSettings()).to_dict()
        self.backend = get_backend(device or rec["device"])  # 'cpu' (NumPy) or 'gpu' (CuPy): RL, wotf, tv
        self.optics = optics
        self.calibration = calibration
        z_min, z_max = (rec["z_min_um"], rec["z_max_um"]) if z is None else z
        self.dz = float(rec["dz_um"] if dz is None else dz)
        self.z_um = z_grid(float(z_min), float(z_max), self.dz)
        self.iterations = int(rec["rl_iterations"] if iterations is None else iterations)
        if self.iterations < 1:
            raise SsdpcError(f"iterations must be >= 1, got {self.iterations}")
        self.model = model or rec.get("model", "lenslet")
        if self.model not in TRANSFER_MODELS:
            raise SsdpcError(f"unknown transfer model '{self.model}'; use one of {', '.join(TRANSFER_MODELS)}")
        self.method = method or rec.get("method", "wotf")
        if self.method not in PHASE_METHODS:
            raise SsdpcError(f"unknown phase method '{self.method}'; use one of {', '.join(PHASE_METHODS)}")
        alpha = rec["tikhonov_alpha"] if alpha is None else alpha
        self.alpha = float(DEFAULT_ALPHA[self.method] if alpha is None else alpha)
        if not self.alpha > 0:
            raise SsdpcError(f"alpha must be > 0, got {self.alpha}")
        self.with_stacks = bool(stacks) or self.method == "rl"
        self.tv_settings = {k: rec[k] for k in ("sign", "dn_max", "tv_lambda", "tv_iterations")}
        self.refraction_increment = float(rec["refraction_increment_um3_pg"])
        self._check_depth_of_field()
        t0 = time.perf_counter()
        self.dark = None if dark is None else float(dark)
        self._flat_views(flat, min_light)
        self._build_operators(progress)
        self.build_seconds = time.perf_counter() - t0

    # ------------------------------------------------------------ set-up
    def _check_depth_of_field(self):
        dof = design(self.optics)["dof_um"]
        reach = max(abs(self.z_um[0]), abs(self.z_um[-1]))
        if reach > dof / 2:
            warnings.warn(
                f"z range reaches {reach:.0f} µm, beyond the depth of field ±{dof / 2:.0f} µm: "
                "planes out there are poorly determined; narrow --z",
                SsdpcWarning,
                stacklevel=3,
            )

    def _flat_views(self, flat, min_light):
        """Per-view flat field (background 1) and the lenslets that get direct light."""
        cal = self.calibration
        geom = extract_views(np.zeros(cal.frame_shape, np.float32), cal)
        self.mask = geom.mask
        self.x_um, self.y_um, self.pixel_um = geom.x_um, geom.y_um, geom.pixel_um
        if flat is not None:
            f = cal.check_frame(flat, name="flat frame")
            fdark = estimate_dark(f, cal) if self.dark is None else self.dark
            fv = np.clip(extract_views(f - fdark, cal).data, 0, None)
        else:
            # without a flat, expect each lenslet's direct light from the transfer model
            fv = None
        self.level = level = self._direct_light(fv)
        lit = level >= min_light * level.max()
        if not lit.any():
            raise SsdpcError("no lenslet receives direct light; check the flat frame and the condenser NA")
        self.lit = np.flatnonzero(lit)
        self.lenslets = [cal.lenslets[i] for i in self.lit]
        if fv is not None:
            sub = fv[self.lit]
            good = sub > 0.3 * np.median(sub[:, self.mask], axis=1)[:, None, None]
            self.flat = np.where(good, sub, np.inf).astype(np.float32)
            self.view_mask = good & self.mask
        else:
            self.flat = None
            self.view_mask = np.broadcast_to(self.mask, (len(self.lit),) + self.mask.shape)
        self.halves = {h: [i for i, ln in enumerate(self.lenslets) if h in ln.halves] for h in HALVES}
        for h, members in self.halves.items():
            if not members:
                raise SsdpcError(
                    f"no lit lenslet in the '{h}' half: the optical axis is not centred among the "
                    "lit lenslets; recalibrate on a white frame or change the condenser NA"
                )

    def _direct_light(self, flat_views):
        """Each lenslet's direct-light level: measured on the flat, else the model's I0_k."""
        if flat_views is not None:
            return np.array([np.median(v[self.mask]) for v in flat_views])
        shape = self.mask.shape
        _, _, i0 = transfer.lenslet_transfer_functions(self.optics, self.calibration.lenslets, shape, self.pixel_um)
        return np.asarray(i0, float)

    def _build_operators(self, progress):
        if self.with_stacks:
            self._build_rl(progress)
        if self.method not in ("wotf", "tv"):
            return
        # one model of the views for both phase methods; the TV solve adds planes beyond the range
        r_z = float(design(self.optics)["r_z_ffl_um"])
        zs, planes = padded_planes(self.z_um, r_z) if self.method == "tv" else (self.z_um, slice(None))
        model = ViewModel(
            self.optics,
            self.lenslets,
            self.mask.shape,
            self.pixel_um,
            zs,
            i0=self.level[self.lit],
            progress=progress,
            backend=self.backend,
        )
        self.wotf = WotfInversion(model.planes(planes), self.alpha)
        if self.method == "tv":
            self.tv = TvInversion(model, planes, r_z, mask=self.mask)

    def _build_rl(self, progress):
        opt = self.optics
        shape = self.mask.shape
        self.psf = LensletPSF(opt, self.lenslets, shape, self.pixel_um, z_max_um=float(np.max(np.abs(self.z_um))))
        shift = float(np.abs(self.psf.tilt).max() * np.max(np.abs(self.z_um))) / self.pixel_um  # parallax, px
        n = [sfft.next_fast_len(int(s + self.psf.support_px + 2 * math.ceil(shift)), real=True) for s in shape]
        self.fft_shape = tuple(n)
        # the OTFs vanish outside |f| ≤ 2ρ (autocorrelation of the sub-aperture): keep that band
        # (+2 frequency steps for the soft pupil edge); what lies outside is below 4e-4 of the DC
        self.band = Band.disk(self.fft_shape, 2 * opt.subaperture_radius * self.pixel_um + 2.0 / min(n))
        otf = {
            h: np.empty((len(m), len(self.z_um)) + self.band.box_shape, np.complex64) for h, m in self.halves.items()
        }
        for i, z in enumerate(self.z_um):
            full = self.band.take(self.psf.otf(float(z), self.fft_shape))
            for h, m in self.halves.items():
                otf[h][:, i] = full[m]
            if progress is not None:
                progress(i + 1, len(self.z_um), "PSF")
        self.psf.clear_cache()
        shared = {}  # the halves run one after the other: they share their FFT scratch buffers
        self.rl = {
            h: MultiViewRL(otf.pop(h), shape, self.view_mask[m], band=self.band, backend=self.backend, workspace=shared)
            for h, m in self.halves.items()
        }
        # DPC transfer functions (in focus) of each axis, on the view grid
        if self.model == "lenslet":
            _, h_phase, i0 = transfer.lenslet_transfer_functions(opt, self.lenslets, shape, self.pixel_um)
            norm = {h: np.mean([h_phase[k] / i0[k] for k in m], axis=0) for h, m in self.halves.items()}
            self.h_dpc = {ax: (0.5 * (norm[a] - norm[b])).astype(np.complex64) for ax, (a, b) in PAIRS.items()}
        else:
            tf = dpc_transfer.dpc_transfer_functions(
                opt, self.lenslets, shape, self.pixel_um, 0.0, model="paper", warn=False
            )
            self.h_dpc = {ax: tf["dpc_phase"][ax] for ax in PAIRS}
        peak = min(float(np.abs(h).max()) for h in self.h_dpc.values())
        if peak < dpc_transfer.WEAK_CONTRAST:
            warnings.warn(
                f"in-focus DPC phase transfer peaks at {peak:.3f}: phase contrast is too weak to "
                "invert; close the condenser aperture",
                SsdpcWarning,
                stacklevel=3,
            )

    # ---------------------------------------------------------- per frame
    def preprocess(self, frame) -> np.ndarray:
        """Dark-subtracted, flat-fielded, non-negative views (K_lit, h, w).

        Parameters
        ----------
        frame : array_like, (H, W)
            Raw frame, camera units.

        Returns
        -------
        ndarray, float32, (K_lit, h, w)
        """
        cal = self.calibration
        img = cal.check_frame(frame)
        warn_saturation(frame)
        dark = estimate_dark(img, cal) if self.dark is None else self.dark
        views = extract_views(img - dark, cal).data[self.lit]
        if self.flat is not None:
            views = views / self.flat
        else:
            views = views / np.array([np.median(v[self.mask]) for v in views])[:, None, None]
        return np.clip(np.where(self.view_mask, views, 0), 0, None).astype(np.float32)

    def reconstruct(self, frame, progress=None, should_stop=None) -> Result:
        """The RI volume of one raw frame (and whatever else the settings ask for).

        Parameters
        ----------
        frame : array_like, (H, W)
            Raw frame, camera units.
        progress : callable, optional
            ``progress(done, total, label)`` per iteration.
        should_stop : callable, optional
            Checked every iteration; True stops with :class:`~napari_ssdpc.errors.Cancelled`.

        Returns
        -------
        Result
            RI, Δn and phase volumes (z, y, x) on the µm grid, the 2D maps, the settings and timings.
        """
        t0 = time.perf_counter()
        views = self.preprocess(frame)
        t1 = time.perf_counter()
        stacks, history, dpc, absorption = {}, {}, {}, None
        if self.with_stacks:
            total = len(HALVES) * self.iterations
            for j, (h, rl) in enumerate(self.rl.items()):
                cb = None if progress is None else (lambda i, n, j=j: progress(j * self.iterations + i, total, "RL"))
                res = rl.run(views[self.halves[h]], self.iterations, progress=cb, should_stop=should_stop)
                stacks[h], history[h] = res.stack, res.relative_change
                if res.stopped:
                    raise Cancelled("reconstruction cancelled")
        t_rl = time.perf_counter()
        if self.with_stacks:
            dpc, absorption = self.dpc_from_stacks(stacks)
        t2 = time.perf_counter()
        phase, report = self.phase_from(views, dpc, progress=progress, should_stop=should_stop)
        dn = phase_to_delta_n(phase, self.optics.wavelength_um, self.dz)
        t3 = time.perf_counter()
        if report is not None:
            history["tv"] = {"objective": report.objective, "relative_change": report.relative_change}
        return Result(
            ri=refractive_index(phase, self.optics.wavelength_um, self.dz, self.optics.medium_index),
            delta_n=dn,
            phase=phase.astype(np.float32),
            absorption=absorption,
            dpc=dpc,
            stacks=stacks,
            z_um=self.z_um.copy(),
            y_um=self.y_um.copy(),
            x_um=self.x_um.copy(),
            convergence=history,
            timings={"preprocess_s": t1 - t0, "rl_s": t_rl - t1, "dpc_s": t2 - t_rl, "phase_s": t3 - t2},
            settings={**self.settings(), **({} if report is None else report.to_dict())},
        )

    def phase_from(self, views, dpc, progress=None, should_stop=None):
        """Phase per slab (Z, ny, nx) by the chosen method, from the preprocessed views ('tv',
        'wotf') or the DPC stacks ('rl'), and the TV solver's report (None for the others).

        Parameters
        ----------
        views : ndarray, float32, (K, h, w)
            Preprocessed views.
        dpc : dict
            {'ud', 'lr'}: DPC stacks (Z, h, w) ('rl' only).
        progress, should_stop : callable, optional

        Returns
        -------
        phase : ndarray, float32, (Z, ny, nx)
            rad per slab.
        report : TvReport or None
        """
        if self.method == "rl":
            h = [self.h_dpc["ud"], self.h_dpc["lr"]]
            return tikhonov_phase([dpc["ud"], dpc["lr"]], h, self.alpha) * self.mask, None
        contrast = np.where(self.view_mask, views - 1.0, 0.0)
        tikhonov = self.wotf.phase(contrast) * self.mask
        if self.method == "wotf":
            return tikhonov, None
        t = self.tv_settings
        phi, report = self.tv.phase(
            contrast,
            warm=tikhonov,
            sign=t["sign"],
            phi_max=2 * math.pi * self.dz * t["dn_max"] / self.optics.wavelength_um,  # Δn = λφ/(2π dz)
            lam=t["tv_lambda"],
            iterations=t["tv_iterations"],
            progress=None if progress is None else (lambda i, n, *_: progress(i, n, "TV")),
            should_stop=should_stop,
        )
        if should_stop is not None and should_stop():
            raise Cancelled("reconstruction cancelled")
        return phi, report

    def dpc_from_stacks(self, stacks):
        """DPC stacks (Eq. 1), each slice normalised by the pair's z-summed intensity, and the
        absorption μ per slice from the sum of the four stacks.

        Parameters
        ----------
        stacks : dict
            {half: (Z, h, w)} Richardson-Lucy stacks.

        Returns
        -------
        dpc : dict
            {'ud', 'lr'}: (Z, h, w).
        absorption : ndarray, (Z, h, w)
            μ per slice.
        """
        dpc = {}
        for ax, (a, b) in PAIRS.items():
            background = np.sum(stacks[a] + stacks[b], axis=0)  # the pair's total intensity per pixel
            dpc[ax] = (dpc_image(stacks[a], stacks[b], background=background) * self.mask).astype(np.float32)
        total = sum(stacks[h] for h in HALVES)
        slice_bg = np.median(total[:, self.mask], axis=1)[:, None, None]
        # intensity ≈ I0 (1 − 2μ) at low frequencies (H_abs(0) = 2 I0): μ per slice
        absorption = -0.5 * (total - slice_bg) / np.maximum(np.sum(total, axis=0), 1e-12) * self.mask
        return dpc, absorption.astype(np.float32)

    def settings(self) -> dict:
        """The settings this reconstructor was built with, for the output metadata."""
        return {
            "z_min_um": float(self.z_um[0]),
            "z_max_um": float(self.z_um[-1]),
            "dz_um": self.dz,
            "rl_iterations": self.iterations,
            "tikhonov_alpha": self.alpha,
            "model": self.model,
            "method": self.method,
            **({k: v for k, v in self.tv_settings.items()} if self.method == "tv" else {}),
            "refraction_increment_um3_pg": self.refraction_increment,
            "lenslets_used": [[ln.row, ln.col] for ln in self.lenslets],
        }
