"""The pupil fitted to a frame of beads: the objective's aberration and the views' focus, with the beads'
centres and sizes free (docs/aberrations.md).

A bead's views through an aberrated pupil differ from the nominal ones in a way a change of the bead
cannot copy: spherical aberration and astigmatism blur the views differently at different depths, and
a lenslet's defocus blurs its view without the parallax a change of depth brings. With the beads'
spheres s (centre, radius, Δn) and the pupil's terms θ (the objective's Zernike coefficients c_j and
one defocus common to the views), the fit minimises the multislice views' misfit over every bead's
region,

    L(s, θ) = Σ_regions ½ Σ_k ‖W (I_k(s; θ) / I0_k − m_k)‖²,

jointly in s and θ by Gauss-Newton with a trust region
(:class:`~napari_ssdpc.reconstruction.beads_and_pupil.BeadsAndPupil`). L has local minima (a bead
fitted far from its place under a wrong pupil keeps it there), so each start pupil's beads come from
the full bead search (:func:`~napari_ssdpc.reconstruction.beads.fit_beads`) with that pupil; a blurred
white frame gives each view's |d_k| (:mod:`~napari_ssdpc.calibration.view_focus`) but not its sign, so
both signs are started (the second only when the first leaves a bead unexplained: a pupil of the wrong
sign cannot explain them) and the lower misfit is kept. A fit that ends without converging (beads
found under a pupil far from the instrument's can sit a wave of phase off and hold it) is started
once more from the pupil it reached, the beads searched again under that pupil. With the beads' index
given (``bead_ri``) their Δn is held in the search too, which then runs over size and depth alone: under
a pupil far from the instrument's (a one-wave spherical aberration) the free search found beads a wave
of phase off, 1.5-2 x too large and 4-6 x too strong.

The terms' uncertainties are the Gauss-Newton covariance σ² (JᵀJ)⁻¹ at the fit, σ the views' noise; a
term the frame does not determine (σ above :data:`UNDETERMINED_WAVES`) is refused in one line. Piston,
tilt and the objective's defocus are left out: they move the objects, not the pupil (the beads'
centres take them).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.bead import Bead
from napari_ssdpc.reconstruction.bead_search import DN_LIMIT
from napari_ssdpc.reconstruction.beads_and_pupil import NOLL, STEPS, BeadsAndPupil
from napari_ssdpc.settings.aberrations import Aberrations

__all__ = ["UNDETERMINED_WAVES", "PupilFit", "check_pupil_fit", "fit_pupil"]

#: A term whose uncertainty is larger than this, waves, is not determined by the frame.
UNDETERMINED_WAVES = 0.05


@dataclass(frozen=True)
class PupilFit:
    """The pupil's terms fitted to a frame of beads, their uncertainties and the beads.

    Attributes
    ----------
    noll : tuple of int
        The objective's fitted terms (Noll indices).
    zernike_waves, zernike_sigma : ndarray, (len(noll),)
        Their coefficients and uncertainties, waves (rms-normalised).
    keys : tuple of (int, int)
        The views' lenslets (row, col).
    defocus_waves : ndarray, (K,)
        Each view's defocus, waves at its sub-aperture's edge.
    defocus_sigma : ndarray, (K,)
        Their uncertainties, waves.
    beads : tuple of Bead
        The beads as fitted with the fitted pupil.
    residual_before, residual_after : float
        The views' mean squared residual over the beads' regions, in noise variances, with the pupil the
        fit started from (the beads fitted again under it) and with the fitted one.
    converged : bool
        The fit ended on its convergence test.
    medium_index : float or None
        The beads' medium: the objective's spherical aberration holds for samples in it.
    """

    noll: tuple[int, ...]
    zernike_waves: np.ndarray
    zernike_sigma: np.ndarray
    keys: tuple[tuple[int, int], ...]
    defocus_waves: np.ndarray
    defocus_sigma: np.ndarray
    beads: tuple[Bead, ...]
    residual_before: float
    residual_after: float
    converged: bool
    medium_index: float | None = None

    def aberrations(self, base: Aberrations) -> Aberrations:
        """``base`` with the fitted objective terms and each view's fitted defocus.

        Parameters
        ----------
        base : Aberrations
            The optics' aberrations (their other terms are kept).

        Returns
        -------
        Aberrations
        """
        return base.with_zernike(self.noll, self.zernike_waves).with_defocus(self.keys, self.defocus_waves)

    def undetermined(self) -> list[str]:
        """The terms whose uncertainty exceeds :data:`UNDETERMINED_WAVES` (names for people)."""
        out = [f"Z{j}" for j, s in zip(self.noll, self.zernike_sigma) if not s <= UNDETERMINED_WAVES]
        bad = [k for k, s in zip(self.keys, self.defocus_sigma) if not s <= UNDETERMINED_WAVES]
        if bad:
            out.append(f"the defocus of {len(bad)} of {len(self.keys)} views")
        return out

    def report(self) -> list[str]:
        """Every term with its uncertainty, and the residual before and after, for people."""
        terms = ", ".join(
            f"Z{j} {c:+.3f} ± {s:.3f}" for j, c, s in zip(self.noll, self.zernike_waves, self.zernike_sigma)
        )
        d, s = self.defocus_waves, self.defocus_sigma
        n = self.medium_index
        medium = "" if n is None else f" (beads in a medium of {n:.3f}: for samples in it)"
        return [
            f"objective (waves rms): {terms}{medium}",
            f"view defocus {np.mean(d):+.3f} waves at the sub-aperture's edge (range {d.min():+.3f} to {d.max():+.3f}, "
            f"± {np.median(s):.3f}; {len(d)} views)",
            f"beads: {len(self.beads)}, residual {self.residual_before:.1f} -> {self.residual_after:.1f} x the noise "
            "(the given pupil -> the fitted one)",
        ]

    def to_dict(self) -> dict:
        """Plain numbers for the calibration's ``optics_fit``."""
        return {
            "noll": list(self.noll),
            "zernike_waves": [float(v) for v in self.zernike_waves],
            "zernike_sigma": [float(v) for v in self.zernike_sigma],
            "defocus_waves": [float(v) for v in self.defocus_waves],
            "defocus_sigma": [float(v) for v in self.defocus_sigma],
            "beads": [b.to_dict() for b in self.beads],
            "residual_before": float(self.residual_before),
            "residual_after": float(self.residual_after),
            "medium_index": None if self.medium_index is None else float(self.medium_index),
        }


def start_defocus(keys: Sequence[tuple[int, int]], focus, sign: float, base: Aberrations) -> np.ndarray:
    """Each view's defocus to start from: ``sign`` x the white frame's |d_k| where measured, else the
    optics' own.

    Parameters
    ----------
    keys : sequence of (int, int)
        The views' lenslets.
    focus : FocusFit or None
    sign : float
        +1 or −1.
    base : Aberrations

    Returns
    -------
    ndarray, (K,)
    """
    measured = {} if focus is None else dict(zip(focus.keys, focus.defocus_waves))
    return np.array(
        [sign * float(measured[k]) if k in measured else base.lenslet(*k).defocus_waves for k in keys], float
    )


def with_pupil(cal, zernike_full, keys, defocus):
    """A copy of the calibration whose optics carry the given objective terms and views' defocus.

    Parameters
    ----------
    cal : Calibration
    zernike_full : sequence of float
        The objective's coefficients from Noll j = 1, waves.
    keys : sequence of (int, int)
        Lenslets (row, col).
    defocus : sequence of float
        Their defocus, waves.

    Returns
    -------
    Calibration
    """
    noll = range(1, len(zernike_full) + 1)
    ab = cal.optics.aberrations.with_zernike(noll, zernike_full).with_defocus(keys, defocus)
    return dataclasses.replace(cal, optics=cal.optics.replace(aberrations=ab.to_dict()))


def fit_pupil(
    config,
    cal,
    flat,
    frame,
    *,
    focus=None,
    bead_ri: float | None = None,
    noll: Sequence[int] = NOLL,
    steps: int = STEPS,
    name: str = "bead frame",
    progress=None,
    should_stop=None,
) -> PupilFit:
    """Fit the objective's terms and every view's defocus to a frame of beads.

    Parameters
    ----------
    config : RunConfig
        The volume the beads lie in (z range and planes) and the multislice model's sampling; its
        optics' medium index is the beads' medium.
    cal : Calibration
        With the condenser fitted (:func:`~napari_ssdpc.reconstruction.optics_fit.fit_optics`).
    flat : ndarray, (H, W)
        The flat frame.
    frame : ndarray, (H, W)
        The raw frame of beads, camera units.
    focus : FocusFit, optional
        Each view's |defocus| from the white frame's rims: when blurred, the fit starts from it with
        each sign and keeps the better.
    bead_ri : float, optional
        The beads' index, when known (their Δn is held).
    noll : sequence of int
        The objective's terms fitted.
    steps : int
        Most evaluations of the residuals in each fit.
    name : str
        The frame's name in messages.
    progress : callable, optional
        ``progress(done, total, label)`` after each stage.
    should_stop : callable, optional
        True stops the fit (:class:`~napari_ssdpc.errors.Cancelled`).

    Returns
    -------
    PupilFit

    Raises
    ------
    SsdpcError
        No bead in the frame, beads of another index than ``bead_ri``, a fit that does not converge or
        does not explain the beads, or terms the frame does not determine (one line each).
    """
    from napari_ssdpc.reconstruction.beads import first_answer, fit_beads
    from napari_ssdpc.reconstruction.reconstructor import Reconstructor

    medium = config.optics.medium_index
    cal = dataclasses.replace(cal, optics=cal.optics.replace(medium_index=medium))
    given = cal.optics.aberrations
    config = config.replace_reconstruction(method="tv").replace(
        optics=config.optics.replace(aberrations=Aberrations()).to_dict()
    )
    bead_dn = None if bead_ri is None else float(bead_ri) - medium
    if bead_dn is not None and not (abs(bead_dn) >= 1e-3 and abs(bead_dn) < DN_LIMIT):
        raise SsdpcError(
            f"--bead-ri {bead_ri} in a medium of {medium}: the beads must differ from the medium by 0.001 to "
            f"{DN_LIMIT} (set --medium-index to the beads' medium)"
        )
    signs = (1.0, -1.0) if focus is not None and focus.blurred else (0.0,)
    total = 3 * (len(signs) + 1) + 1  # a start that explains every bead ends the starts early
    done = 0

    def step(label: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total, label)

    base_z = np.zeros(max(max(noll), len(given.objective_zernike_waves)))
    base_z[: len(given.objective_zernike_waves)] = given.objective_zernike_waves
    zernike0 = base_z[np.asarray(noll) - 1]
    keys = [(ln.row, ln.col) for ln in cal.lenslets]
    # each start: the objective's terms and each lenslet's defocus (None: the given optics')
    starts: list[tuple[np.ndarray, np.ndarray | None]] = [
        (base_z, start_defocus(keys, focus, sign, given) if sign else None) for sign in signs
    ]
    best, again = None, True
    while starts:
        start_z, defocus = starts.pop(0)
        start = cal if defocus is None else with_pupil(cal, start_z, keys, defocus)
        rec = Reconstructor(config, start, flat=flat)
        views, _ = rec.views.measure(frame, name)
        dn, noise = first_answer(rec, views, should_stop=should_stop)
        step("the first answer")
        settings = config.reconstruction.multislice
        beads = fit_beads(
            rec.views, views, dn, rec.z_um, noise=noise, optics=rec.optics, settings=settings,
            delta_n=bead_dn, should_stop=should_stop,
        )  # fmt: skip
        step("the beads under the start pupil")
        if not beads:
            raise SsdpcError(f"no bead found in {name}: give a frame of beads (its first answer holds no object)")
        spheres = np.array([[*b.centre_um, b.diameter_um / 2, b.delta_n] for b in beads])
        view_keys = [(ln.row, ln.col) for ln in rec.views.lenslets]
        d0 = np.array([rec.optics.aberrations.lenslet(*k).defocus_waves for k in view_keys], float)
        job = BeadsAndPupil(rec.views, views, spheres, settings, noll, start_z, d0, rec.backend)
        q0 = job.pack(spheres, start_z[np.asarray(noll) - 1])
        fitted = job.fit(q0, fixed_dn=bead_dn, steps=steps, should_stop=should_stop)
        step("beads and pupil together")
        if best is None or fitted.cost < best[0].cost:
            best = (fitted, job, noise, rec)
        # a pupil of the wrong sign cannot explain the beads: the first start that explains every bead
        # is the answer (the other's search and fit, half the time, are saved)
        if fitted.converged and all(
            b.explained for b in job.beads(fitted.q, True, noise, rec.optics, config.reconstruction.multislice)
        ):
            best = (fitted, job, noise, rec)
            break
        if not fitted.converged and again:
            # beads searched under a pupil far from the instrument's can sit a wave of phase off (a
            # one-wave spherical aberration: found 1.5-2 x too large and 4-6 x too strong) and hold the
            # pupil's fit: they are searched again under the pupil it reached, and fitted from there
            _, z_end, d_end = job.unpack(fitted.q)
            reached = start_z.copy()
            reached[np.asarray(noll) - 1] = z_end
            ended = dict(zip(view_keys, d_end))
            starts.insert(0, (reached, np.array([ended.get(k, given.lenslet(*k).defocus_waves) for k in keys])))
            again = False
    assert best is not None  # there is at least one start
    fitted, job, noise, rec = best
    spheres, zernike, defocus = job.unpack(fitted.q)
    sigma = job.sigmas(fitted, noise)
    n_spheres = 5 * len(spheres)
    beads = job.beads(fitted.q, fitted.converged, noise, rec.optics, config.reconstruction.multislice)
    # each view's uncertainty: the common δ's and, where the rims gave d0_k, theirs
    view_keys = [(ln.row, ln.col) for ln in rec.views.lenslets]
    rims = {} if focus is None or not focus.blurred else dict(zip(focus.keys, focus.sigma_waves))
    defocus_sigma = np.hypot(sigma[-1], [rims.get(k, 0.0) for k in view_keys])
    job.defocus0 = start_defocus(view_keys, None, 1.0, given)  # the given optics' pupil
    before = job.fit(
        job.pack(spheres, zernike0), fixed_dn=bead_dn, hold_pupil=True, steps=steps, should_stop=should_stop
    )
    done = total - 1  # the starts not needed are skipped
    step("the beads under the given pupil")
    result = PupilFit(
        tuple(noll),
        zernike,
        sigma[n_spheres : n_spheres + len(noll)],
        tuple(view_keys),
        defocus,
        defocus_sigma,
        tuple(beads),
        job.residual_over_noise(before.cost, noise),
        job.residual_over_noise(fitted.cost, noise),
        fitted.converged,
        medium,
    )
    check_pupil_fit(result, bead_ri)
    return result


def check_pupil_fit(fit: PupilFit, bead_ri: float | None) -> None:
    """Refuse a fit that did not converge, leaves the beads unexplained or does not determine its terms.

    Parameters
    ----------
    fit : PupilFit
    bead_ri : float or None
        The beads' index the user gave (a bead left unexplained then may be of another index).

    Raises
    ------
    SsdpcError
        One line that says which.
    """
    if not fit.converged:
        terms = ", ".join(f"Z{j} {c:+.3f}" for j, c in zip(fit.noll, fit.zernike_waves))
        raise SsdpcError(
            f"the fit of the pupil to the beads did not converge (where it stopped: {terms} waves, residual "
            f"{fit.residual_before:.1f} -> {fit.residual_after:.1f} x the noise); nothing written (give a frame "
            "with fewer, isolated beads, or optics nearer the instrument's to start from: --optics)"
        )
    outside = [b for b in fit.beads if b.residual_over_noise is None]
    if outside:
        x, y, z = outside[0].centre_um
        raise SsdpcError(
            f"the fit moved a bead out of the views of its region (to ({x:.1f}, {y:.1f}, {z:.1f}) µm): objects "
            "that are not beads, or an instrument the pupil's terms do not describe; nothing written"
        )
    unexplained = [b for b in fit.beads if not b.explained]
    if unexplained:
        b = unexplained[0]
        cause = (
            f"beads of another index than --bead-ri {bead_ri}, or an instrument the pupil's terms do not describe"
            if bead_ri is not None
            else "an instrument the pupil's terms do not describe, or objects that are not beads"
        )
        raise SsdpcError(
            f"the fitted pupil leaves {b.residual_over_noise or float('nan'):.1f} x the noise over the bead at "
            f"({b.centre_um[0]:.1f}, {b.centre_um[1]:.1f}, {b.centre_um[2]:.1f}) µm (a bead fits to "
            f"{b.stop_over_noise:.1f}): {cause}; nothing written"
        )
    missing = fit.undetermined()
    if missing:
        raise SsdpcError(
            f"the frame does not determine {', '.join(missing)} (uncertainty over {UNDETERMINED_WAVES} waves); "
            "nothing written: give a frame with more beads spread over the field and in depth"
        )
