"""Each view's focus, measured on the white frame from the sharpness of its elemental image's rim.

With the condenser open the field stop is lit incoherently, and every EI is the stop's disk imaged
through its lenslet's sub-aperture: the disk convolved with the view's PSF at z = 0. A lenslet whose
sensor is not at its focal plane (an MLA off the Fourier lens's focus, lenslets that differ in focal
length) blurs its rim: the defocus d_k of its pupil (waves at the sub-aperture's edge,
docs/aberrations.md) widens the PSF as a depth of −2 n d_k / (λ ρ²) would, without moving the
parallax. The rim of every lenslet wholly inside the pupil is fitted, where no neighbouring EI
lights it, by the disk (its radius free, its light falling off quadratically towards the rim as
Köhler illumination does across the field) convolved with the PSF of a few defocus values
(:class:`~napari_ssdpc.physics.psf.LensletPSF`, the one pupil) times a scale plus a background;
the misfit's minimum over |d_k| (a parabola through the best three) is the answer and its
curvature the uncertainty. A pure defocus blurs alike for ±d_k: the rim gives its size, not its
sign (a frame of objects at known depths gives that).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import cpu
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.apertures import disk_fraction
from napari_ssdpc.physics.psf import LensletPSF
from napari_ssdpc.settings.aberrations import Aberrations, LensletTerms
from napari_ssdpc.settings.optics import Optics

__all__ = ["FocusFit", "fit_view_focus", "rim_defocus", "rims_notice", "rims_unmodelled"]

#: The defocus values the rims are compared with, waves at the sub-aperture's edge.
DEFOCUS_WAVES = np.round(np.arange(0.0, 1.51, 0.1), 3)
#: Rim radii tried about the calibration's, px.
RADIUS_STEPS_PX = np.arange(-1.0, 1.01, 0.25)
#: A median view defocus beyond this is reported as blurred rims, waves: simulated white frames read
#: 0.07 in focus and 0.005 for a view at 0.16 (near focus the rim's width changes as d², and the
#: model's misfit of about 1 % hides it), 0.25-0.91 within 0.035 from 0.29 to 0.89.
BLURRED_WAVES = 0.2
#: The quick look every white frame's calibration takes (:func:`rim_defocus`): the views nearest the
#: axis, defocus every 0.2 waves (0.35 s on 2 cores; simulated white frames read 0.09 in focus and
#: 0.47 for views at 0.48, where all 16 views and 0.1 steps read 0.07 and 0.48).
QUICK_LENSLETS, QUICK_DEFOCUS = 2, np.round(np.arange(0.0, 1.61, 0.2), 3)
#: The PSF kernel the rims are blurred with, px.
KERNEL_PX = 41
#: The rim's band: this far inside and outside the EI radius, px.
INSIDE_PX, OUTSIDE_PX = 10, 8


@dataclass(frozen=True)
class FocusFit:
    """Each view's defocus measured on the white frame's EI rims.

    Attributes
    ----------
    keys : list of (int, int)
        The lenslets fitted, (row, col).
    defocus_waves, sigma_waves : ndarray, (K,)
        |d_k| and its standard uncertainty, waves at the sub-aperture's edge.
    misfit_before, misfit_after : float
        The rims' rms misfit at d = 0 and at the fitted d, as a fraction of the EI's brightness.
    """

    keys: list
    defocus_waves: np.ndarray
    sigma_waves: np.ndarray
    misfit_before: float
    misfit_after: float

    def aberrations(self, base: Aberrations) -> Aberrations:
        """``base`` with each fitted lenslet's defocus (its size: the sign is taken positive).

        Parameters
        ----------
        base : Aberrations

        Returns
        -------
        Aberrations
        """
        return base.with_defocus(self.keys, self.defocus_waves)

    @property
    def blurred(self) -> bool:
        """Whether the views are out of focus beyond what an in-focus instrument reads
        (:data:`BLURRED_WAVES`)."""
        return bool(np.median(self.defocus_waves) > BLURRED_WAVES)

    def notice(self) -> str:
        """One line for people: the views' rims are blurred, what it means and what to do."""
        return (
            f"{_blurred_rims(float(np.median(self.defocus_waves)))}; refocus the camera onto the MLA's focus (the rims "
            "sharpest), or expect blurred views: the sign of the defocus needs a frame of objects at known depths"
        )

    def report(self) -> list[str]:
        """The views' defocus (mean, range, uncertainty) and the misfit before and after."""
        d, s = self.defocus_waves, self.sigma_waves
        return [
            f"view defocus |d| {np.mean(d):.3f} waves at the sub-aperture's edge (range {d.min():.3f}-{d.max():.3f}, "
            f"± {np.median(s):.3f} from the noise; {len(d)} lenslets; below {BLURRED_WAVES} waves the rims cannot "
            "tell it from focus)",
            f"EI rim misfit {100 * self.misfit_before:.2f} % -> {100 * self.misfit_after:.2f} % of the EI's brightness",
        ]


def _blurred_rims(d: float) -> str:
    return (
        f"the elemental images' rims are blurred as by a defocus of {d:.2f} waves at each sub-aperture's edge "
        "(an in-focus instrument reads under 0.1): the camera is not in the lenslets' focal plane, or the MLA "
        "not in the Fourier lens's"
    )


def rims_notice(d: float, name: str = "the white frame") -> str:
    """One line for every frame reconstructed with views this far out of focus and optics that do not
    model it: what it does to the numbers and the fix, `ssdpc fit-optics`.

    Parameters
    ----------
    d : float
        The views' defocus the rims show (:func:`rim_defocus`), waves at the sub-aperture's edge.
    name : str
        The frame the rims were measured on.

    Returns
    -------
    str
    """
    return (
        f"{name}: {_blurred_rims(d)}, and the optics in use do not model it (two beads read 0.3 x their Δn "
        "through such views, docs/validation.md): refocus the camera onto the lenslets' focus and recalibrate, or "
        "fit the views' focus and the pupil to a frame of beads with `ssdpc fit-optics BEADS.tif --calibration "
        "CAL --flat FLAT --white WHITE -o FITTED.json`"
    )


def rims_unmodelled(d: float, optics: Optics) -> bool:
    """Whether views this far out of focus (:func:`rim_defocus`) are beyond an in-focus instrument's
    (:data:`BLURRED_WAVES`) while ``optics`` give no lenslet a defocus.

    Parameters
    ----------
    d : float
        Waves at the sub-aperture's edge.
    optics : Optics

    Returns
    -------
    bool
    """
    return d > BLURRED_WAVES and not any(t.defocus_waves != 0 for t in optics.aberrations.lenslets)


def rim_defocus(white, cal, optics: Optics) -> float | None:
    """A quick look at the views' focus on a white frame: the median |d_k| of the views nearest the
    optical axis (:data:`QUICK_LENSLETS`, :data:`QUICK_DEFOCUS`); beyond :data:`BLURRED_WAVES` the
    views are out of focus.

    Parameters
    ----------
    white : ndarray, (H, W)
        The white frame, camera units.
    cal : Calibration
        Its calibration.
    optics : Optics

    Returns
    -------
    float or None
        Waves at the sub-aperture's edge; None where no rim is free of its neighbours' light.
    """
    try:
        fit = fit_view_focus(white, cal, optics, most_central=QUICK_LENSLETS, defocus_waves=QUICK_DEFOCUS)
    except SsdpcError:
        return None
    return round(float(np.median(fit.defocus_waves)), 3)


def _rims(white, cal, most_central: int | None = None):
    """For each lenslet wholly inside the pupil and on the frame (the ``most_central`` nearest the
    optical axis, or all): its index, window origin and the rim pixels no neighbouring EI lights (a
    boolean mask on the window)."""
    img = np.asarray(white, float)
    r_ei = float(cal.ei_radius_px)
    half = int(np.ceil(r_ei + OUTSIDE_PX + 2))
    centres = np.asarray(cal.centres_px, float)
    inside = [i for i, ln in enumerate(cal.lenslets) if ln.fraction >= 0.999]
    if most_central is not None:
        inside.sort(key=lambda i: float(np.hypot(*(centres[i] - np.asarray(cal.grid.axis_px, float)))))
    out = []
    for i in inside:
        cx, cy = centres[i]
        x0, y0 = int(round(cx)) - half, int(round(cy)) - half
        if x0 < 0 or y0 < 0 or x0 + 2 * half >= img.shape[1] or y0 + 2 * half >= img.shape[0]:
            continue
        yy, xx = np.mgrid[y0 : y0 + 2 * half + 1, x0 : x0 + 2 * half + 1]
        r = np.hypot(xx - cx, yy - cy)
        others = np.delete(centres, i, axis=0)
        nearest = np.min(np.hypot(xx[..., None] - others[:, 0], yy[..., None] - others[:, 1]), axis=-1)
        mask = (r > r_ei - INSIDE_PX) & (r < r_ei + OUTSIDE_PX) & (nearest > r_ei + OUTSIDE_PX + 2)
        if mask.sum() > 50:
            out.append((i, (x0, y0), mask, img[y0 : y0 + 2 * half + 1, x0 : x0 + 2 * half + 1]))
            if most_central is not None and len(out) == most_central:
                break
    return out


def _disks(rims, cal, shape) -> list:
    """Per rim, the spectra (rfft2 on ``shape``) of the stop's disk at each radius tried and of the
    same disk falling off towards its rim (Köhler illumination's fall-off): [(disk, disk r²/R²) per
    radius]."""
    centres, r_ei = np.asarray(cal.centres_px, float), float(cal.ei_radius_px)
    out = []
    for i, (x0, y0), _, data in rims:
        yy, xx = np.mgrid[: data.shape[0], : data.shape[1]]
        dx, dy = xx + x0 - centres[i, 0], yy + y0 - centres[i, 1]
        r2 = (dx * dx + dy * dy) / r_ei**2
        disks = [disk_fraction(dx, dy, r_ei + step, 1.0) for step in RADIUS_STEPS_PX]
        out.append([(cpu().rfft2(disk, s=shape), cpu().rfft2(disk * r2, s=shape)) for disk in disks])
    return out


def _misfits(rims, cal, optics: Optics, defocus_waves, progress=None) -> np.ndarray:
    """The rims' least misfit (over radius, scale, fall-off and background) for every defocus, (K, D).

    Each model is the disk convolved with the view's PSF (its 'same' part: the kernel's centre on
    the window's pixel); the disks' spectra are computed once for every defocus."""
    lenslets = [cal.lenslets[i] for i, *_ in rims]
    n = rims[0][3].shape[0]
    shape = (sfft.next_fast_len(n + KERNEL_PX - 1, real=True),) * 2
    disks = _disks(rims, cal, shape)  # the same for every defocus
    c = KERNEL_PX // 2
    out = np.zeros((len(rims), len(defocus_waves)))
    for j, d in enumerate(defocus_waves):
        terms = tuple(LensletTerms(row=ln.row, col=ln.col, defocus_waves=float(d)) for ln in lenslets)
        # the path behind the field stop: the lenslets alone (the objective's phase leaves the stop's image)
        behind = {"lenslets": terms, "objective_zernike_waves": ()}
        blurred = optics.replace(aberrations=optics.aberrations.model_copy(update=behind).to_dict())
        kernels = LensletPSF(blurred, lenslets, shape=(KERNEL_PX,) * 2, support_px=KERNEL_PX).kernels(0.0)
        for k, (_, _, mask, data) in enumerate(rims):
            kernel = cpu().rfft2(kernels[k], s=shape)
            best = np.inf
            for spectra in disks[k]:
                a = np.stack(
                    [cpu().irfft2(spec * kernel, s=shape)[c : c + n, c : c + n][mask] for spec in spectra]
                    + [np.ones(int(mask.sum()))],
                    axis=1,
                )
                coef, *_ = np.linalg.lstsq(a, data[mask], rcond=None)
                best = min(best, float(np.sum((a @ coef - data[mask]) ** 2)))
            out[k, j] = best
        if progress is not None:
            progress(j + 1, len(defocus_waves))
    return out


def fit_view_focus(
    white, cal, optics: Optics, progress=None, *, most_central: int | None = None, defocus_waves=DEFOCUS_WAVES
) -> FocusFit:
    """Fit each view's defocus to the rims of the white frame's elemental images.

    Parameters
    ----------
    white : ndarray, (H, W)
        The white frame (condenser open, no sample), camera units.
    cal : Calibration
        Its calibration (EI centres and radius).
    optics : Optics
        The optics (the rims are the field stop's image through the lenslets alone: the objective's
        aberrations act before the stop and are left out of the model).
    progress : callable, optional
        ``progress(done, total)`` per defocus value.
    most_central : int, optional
        Fit only this many lenslets, those nearest the optical axis (a quick look:
        :func:`rim_defocus`); all by default.
    defocus_waves : ndarray, (D,)
        The defocus values the rims are compared with, evenly spaced from 0, waves.

    Returns
    -------
    FocusFit

    Raises
    ------
    SsdpcError
        No elemental image whose rim is free of its neighbours' light.
    """
    rims = _rims(cal.check_frame(white, "white frame"), cal, most_central)
    if not rims:
        raise SsdpcError(
            "no elemental image of the white frame has a rim free of its neighbours' light; check the calibration "
            "(its EI radius) and that the frame is a white frame"
        )
    defocus_waves = np.asarray(defocus_waves, float)
    misfit = _misfits(rims, cal, optics, defocus_waves, progress)
    n = np.array([mask.sum() for _, _, mask, _ in rims], float)
    level = np.array([np.percentile(data[mask], 95) for _, _, mask, data in rims])
    best = np.argmin(misfit, axis=1)
    d, sigma = np.empty(len(rims)), np.empty(len(rims))
    step = float(defocus_waves[1] - defocus_waves[0])
    for k, j in enumerate(best):
        j = int(np.clip(j, 1, len(defocus_waves) - 2))
        y0, y1, y2 = misfit[k, j - 1 : j + 2]
        curv = (y0 - 2 * y1 + y2) / step**2
        shift = 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2) if curv > 0 else 0.0
        d[k] = max(float(defocus_waves[j] + np.clip(shift, -1, 1) * step), 0.0)
        noise = misfit[k, best[k]] / max(n[k] - 5, 1)
        sigma[k] = np.sqrt(2 * noise / curv) if curv > 0 else np.inf
    rms = lambda col: float(np.sqrt(np.mean(col / n) / np.mean(level**2)))
    return FocusFit(
        keys=[(cal.lenslets[i].row, cal.lenslets[i].col) for i, *_ in rims],
        defocus_waves=d,
        sigma_waves=sigma,
        misfit_before=rms(misfit[:, 0]),
        misfit_after=rms(misfit[np.arange(len(rims)), best]),
    )
