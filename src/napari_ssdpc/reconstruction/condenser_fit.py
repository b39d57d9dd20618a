"""The condenser as it is: its NA and its centre, fitted to the lenslets' light on a flat frame.

A lenslet's direct light is the area of the condenser disk |u − c| ≤ NA_c/λ inside its own
sub-aperture (paper Eq. 2; docs/aberrations.md): the overlap of two circles. Over the lenslets
wholly inside the objective's pupil, the flat's levels (scaled to their largest) are fitted by
those overlaps times the best scale (the lamp's brightness is unknown: it is solved for in closed
form at every step) with NA_c and the centre c = (c_x, c_y) free (scipy's least squares). The
lenslets that straddle the disk's edge carry the information: a disk off axis lights the lenslets
on one side more than their mirror images. The uncertainties are the fit's covariance scaled by
the misfit it leaves (vignetting, unequal lenslets and noise alike).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.pupil import Pupil
from napari_ssdpc.reconstruction import consistency
from napari_ssdpc.settings.lenslets import circle_overlap_fraction
from napari_ssdpc.settings.optics import Optics

__all__ = ["CondenserFit", "fit_condenser"]

#: Fewest lenslets inside the pupil a fit of three numbers and a scale takes.
MIN_LENSLETS = 6
#: Fewest lenslets lit (direct light above LIT of the brightest) that determine NA, centre and scale.
MIN_LIT = 5
LIT = 0.02
#: A misfit left beyond this (fraction of the brightest lenslet's light) is reported: simulated flats
#: leave 0.1-0.4 %, lenslets that transmit 3 % unevenly 2 %.
UNEXPLAINED = 0.05
#: Largest uncertainty of the NA or the centre, NA units, that counts as determined.
MAX_SIGMA_NA = 0.01


@dataclass(frozen=True)
class CondenserFit:
    """The condenser's NA and centre fitted to a flat frame.

    Attributes
    ----------
    na, na_sigma : float
        The NA and its standard uncertainty.
    offset_na, offset_sigma : (float, float)
        The disk's centre off the optical axis (x, y), NA, and its standard uncertainty.
    rms_before, rms_after : float
        The levels' misfit with the given optics and with the fitted condenser, as a fraction of the
        brightest lenslet's light.
    lenslets : int
        The lenslets fitted (those wholly inside the objective's pupil).
    """

    na: float
    na_sigma: float
    offset_na: tuple[float, float]
    offset_sigma: tuple[float, float]
    rms_before: float
    rms_after: float
    lenslets: int

    def optics(self, optics: Optics) -> Optics:
        """The optics with this condenser (NA and centre), everything else as given.

        Parameters
        ----------
        optics : Optics

        Returns
        -------
        Optics
        """
        ab = optics.aberrations.model_copy(update={"condenser_offset_na": self.offset_na})
        return optics.replace(condenser_na=round(self.na, 5), aberrations=ab.to_dict())

    def to_dict(self, given: Optics) -> dict:
        """The fit as plain values for a calibration's ``optics_fit`` (with the NA it corrected).

        Parameters
        ----------
        given : Optics
            The optics the fit started from.

        Returns
        -------
        dict
        """
        return {
            "na": self.na,
            "na_sigma": self.na_sigma,
            "offset_na": list(self.offset_na),
            "offset_sigma": list(self.offset_sigma),
            "rms_before": self.rms_before,
            "rms_after": self.rms_after,
            "lenslets": self.lenslets,
            "na_given": given.condenser_na,
        }

    @property
    def unexplained(self) -> bool:
        """Whether the lenslets' light differs from the condenser's overlaps beyond :data:`UNEXPLAINED`."""
        return self.rms_after > UNEXPLAINED

    def report(self) -> list[str]:
        """The fitted terms with their uncertainties and the misfit before and after, one line each
        (and what an unexplained misfit means)."""
        (cx, cy), (sx, sy) = self.offset_na, self.offset_sigma
        return [
            f"condenser NA {self.na:.4f} ± {self.na_sigma:.4f}",
            f"condenser centre off axis (x, y) ({cx:+.4f} ± {sx:.4f}, {cy:+.4f} ± {sy:.4f}) NA",
            f"flat levels misfit {100 * self.rms_before:.2f} % -> {100 * self.rms_after:.2f} % of the brightest "
            f"lenslet ({self.lenslets} lenslets)",
        ] + (
            [
                f"the lenslets' light differs from the condenser's overlaps by {100 * self.rms_after:.1f} % rms: "
                "lenslets that transmit unequally, sub-apertures off their place, or a flat with a sample in it"
            ]
            if self.unexplained
            else []
        )


def _residuals(levels, u_k, rho_k, wavelength_um):
    """The levels' misfit r(NA, c_x, c_y) at the best scale (closed form), (K,)."""

    def residuals(p):
        na, cx, cy = p
        d = np.hypot(u_k[:, 0] - cx / wavelength_um, u_k[:, 1] - cy / wavelength_um)
        m = circle_overlap_fraction(d, rho_k, max(na, 1e-6) / wavelength_um) * rho_k**2
        scale = (m @ levels) / max(m @ m, 1e-30)
        return scale * m - levels

    return residuals


def fit_condenser(levels, lenslets, optics: Optics) -> CondenserFit:
    """Fit the condenser's NA and centre to a flat frame's lenslet levels.

    Parameters
    ----------
    levels : ndarray, (K,)
        Every lenslet's light above the dark level on the flat, camera units
        (:meth:`~napari_ssdpc.reconstruction.contrast.ViewContrast.lenslet_levels`).
    lenslets : list of Lenslet
        The calibration's lenslets, in the same order.
    optics : Optics
        The optics given: the start, and each lenslet's own sub-aperture.

    Returns
    -------
    CondenserFit

    Raises
    ------
    SsdpcError
        Too few lenslets inside the pupil, no light, or a flat that does not determine the
        condenser (every lenslet lit whole: the condenser open).
    """
    levels = np.asarray(levels, float)
    if levels.shape != (len(lenslets),):
        raise SsdpcError(f"{levels.shape[0]} levels for {len(lenslets)} lenslets; give one level per lenslet")
    inner = np.array([ln.fraction >= 0.999 for ln in lenslets])
    if inner.sum() < MIN_LENSLETS:
        raise SsdpcError(
            f"only {int(inner.sum())} lenslets lie wholly inside the objective's pupil (at least {MIN_LENSLETS} "
            "fit the condenser); check the calibration"
        )
    top = float(np.max(levels[inner]))
    if not top > 0:
        raise SsdpcError("the flat frame has no light in its lenslets; record it with the lamp on and no sample")
    lit = int(np.sum(levels[inner] > LIT * top))
    if lit < MIN_LIT:
        raise SsdpcError(
            f"the flat frame does not determine the condenser: only {lit} lenslets inside the pupil are lit (at least "
            f"{MIN_LIT} fit its NA and centre); record a flat at a larger condenser NA to fit the condenser"
        )
    u_k, rho_k, _ = Pupil.of(optics).lenslet_arrays(lenslets)
    residuals = _residuals(levels[inner] / top, u_k[inner], rho_k[inner], optics.wavelength_um)
    start = np.array([consistency.apparent_condenser_na(levels, lenslets, optics).na, 0.0, 0.0])
    fit = least_squares(residuals, start, x_scale=0.01, diff_step=1e-4)
    dof = max(int(inner.sum()) - 4, 1)
    jtj = fit.jac.T @ fit.jac
    if np.linalg.cond(jtj) > 1e12:
        raise SsdpcError(_UNDETERMINED)
    sigma = np.sqrt(np.diag(np.linalg.inv(jtj)) * (fit.fun @ fit.fun) / dof)
    if not np.all(sigma <= MAX_SIGMA_NA):
        raise SsdpcError(_UNDETERMINED)
    given = np.array([optics.condenser_na, *optics.aberrations.condenser_offset_na])
    rms = lambda r: float(np.sqrt(np.mean(r**2)))
    return CondenserFit(
        na=float(fit.x[0]),
        na_sigma=float(sigma[0]),
        offset_na=(float(fit.x[1]), float(fit.x[2])),
        offset_sigma=(float(sigma[1]), float(sigma[2])),
        rms_before=rms(residuals(given)),
        rms_after=rms(fit.fun),
        lenslets=int(inner.sum()),
    )


_UNDETERMINED = (
    "the flat frame does not determine the condenser: too few lenslets straddle the edge of its disk (a condenser "
    "open or nearly so lights them all whole); record the flat at the raw frames' condenser NA"
)
