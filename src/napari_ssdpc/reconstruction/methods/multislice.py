"""The 'multislice' method: the 'tv' solution refined with a multislice model of the views.

The first-order model (paper Eqs. 2-4) that 'tv' inverts holds for weak objects only; a bead of a
few radians through its centre refracts and scatters light several times, and its first-order
inverse loses mass and trails along z. Here the 'tv' solution is the start of a nonlinear fit: the
views predicted by a multislice (beam propagation) model of the instrument
(:class:`~napari_ssdpc.physics.views_multislice.ViewsMultislice`: Köhler source points, phase
screens and angular-spectrum propagation through the Δn volume, the objective pupil and every
lenslet's sub-aperture, flat-fielded) are fitted to the measured views,

    minimise  ½ Σ_k ‖W (I_k(Δn) / I0_k − m_k)‖² + μ TV_ε(Δn)   subject to  Δn ∈ C

with C the sign, the bound and the field stop of 'tv' and the region's medium edge (below), by the
one nonlinear solver of the package (:func:`~napari_ssdpc.reconstruction.nonlinear.projected_gradient`:
accelerated projected gradient with backtracking and restart, on the setup's backend in float32),
the gradient by the model's adjoint, as in multislice / beam propagation tomography (Kamilov et al.,
IEEE TCI 2016; Chowdhury et al., Optica 2019).

The model covers a square region around the objects of the 'tv' solution (their footprint plus a
margin for the light they scatter) and every plane of the volume: nothing is cut out along z, so an
object that shares an axis with another, or lies deeper than 'tv' puts it, stays in the fit. The
model's grid is periodic, and a Δn uniform over a plane of it is a phase delay no view sees: a band
along the region's edge (``medium_edge_um``) is held at the medium, which ties every plane's mean
to it (without it the sign constraint pumps that free mean into a floor of Δn over the region).
When the fit replaced the 'tv' answer in the region, outside it (and added inside it) is the rest
of the frame: 'tv' of the views with the region's modelled views taken out
(:mod:`~napari_ssdpc.reconstruction.rest_of_frame`), not the first 'tv' solution, which spread the
strong objects' unexplained light over the field. Every object of the region is reported with its
centre, its dry mass and the residual of the views over it, and a warning names those the model
does not explain.
"""

from __future__ import annotations

import json
import math
import time
import warnings

import numpy as np

from napari_ssdpc.errors import SsdpcWarning
from napari_ssdpc.physics.views_multislice import ViewsMultislice
from napari_ssdpc.reconstruction.bead import Bead
from napari_ssdpc.reconstruction.fit_objects import explained_limit, fit_objects
from napari_ssdpc.reconstruction.memory import available_memory
from napari_ssdpc.reconstruction.methods.base import PhaseMethod, Setup, Solution
from napari_ssdpc.reconstruction.methods.tv import TvMethod
from napari_ssdpc.reconstruction.multislice_region import (
    medium_edge,
    object_support,
    objects_roi,
    region_of,
    unexplained_columns,
)
from napari_ssdpc.reconstruction.nonlinear import Fit, Unknowns, discrepancy_stop, projected_gradient
from napari_ssdpc.reconstruction.proximal import bounds
from napari_ssdpc.reconstruction.regularised import TvState
from napari_ssdpc.reconstruction.rest_of_frame import with_rest
from napari_ssdpc.reconstruction.sphere_start import sphere_starts

__all__ = ["MultisliceMethod"]

#: Stop when the relative change of Δn falls below this.
TOLERANCE = 1e-3
#: Fits held to the objects' support, each freeing the columns the one before left unexplained.
SUPPORT_ROUNDS = 3
#: A start is as good as the stop when its misfit exceeds it by less than this many standard
#: deviations of a mean of n squared Gaussian residuals (relative: sqrt(2 / n)).
WITHIN_STOP_SIGMAS = 3.0


def _starts_report(starts: dict, chosen: str, beads: list, seconds: float) -> dict:
    """The report's record of the starts: their misfits over the noise, the one taken, the beads
    fitted for the sphere start (a series' next frame fits its beads from them) and the bead
    fit's time, s."""
    return {
        "multislice_starts_over_noise": starts,
        "multislice_start": chosen,
        "multislice_start_beads": [b.to_dict() for b in beads],
        "multislice_sphere_start_seconds": seconds,
    }


def _sign_of(start: Solution) -> str:
    """The sign the 'tv' start solved with ('auto' resolved), from its end state."""
    if not isinstance(start.state, TvState):
        raise TypeError("the multislice refinement starts from a 'tv' solution with its end state")
    return start.state.sign


class MultisliceMethod(PhaseMethod):
    """'tv', then a nonlinear fit of a multislice model of the views in a region around the objects."""

    name = "multislice"
    starts_from = "tv"

    def __init__(self, setup: Setup, tv: TvMethod):
        self.setup, self.tv = setup, tv
        self._models: dict = {}  # the last models of the views, by region and planes

    @classmethod
    def _build(cls, setup, progress):
        return cls(setup, TvMethod.build(setup, progress))  # the models of the views: per region

    @classmethod
    def on(cls, start: PhaseMethod) -> MultisliceMethod:
        """The refinement of a built 'tv' method (its operators and its last solve shared).

        Parameters
        ----------
        start : TvMethod
            Built, with its setup.

        Returns
        -------
        MultisliceMethod
            Its start is ``start`` itself.
        """
        if not isinstance(start, TvMethod):
            raise TypeError(f"the multislice refinement starts from 'tv', not '{start.name}'")
        return cls(start.setup, start)

    @property
    def start(self) -> TvMethod:
        """The 'tv' method it refines."""
        return self.tv

    def _solve(self, views, stacks, warm, progress, should_stop):
        s, v = self.setup, self.setup.views
        ms, bk = s.settings.multislice, s.backend
        # the tv answer of this frame when it was just computed (napari, the demo), else solved now
        start = self.tv.solve_or_reuse(views, warm=warm, progress=progress, should_stop=should_stop)
        t0 = time.perf_counter()
        to_dn = s.optics.wavelength_um / (2 * math.pi * s.dz_um)  # Δn = λφ/(2π dz)
        dn = np.asarray(start.phase, np.float32) * to_dn
        if ms.roi_um is not None:
            rows, cols = region_of(ms.roi_um, v.x_um, v.y_um)
        else:
            rows, cols = objects_roi(dn, v.x_um, v.y_um, ms.roi_margin_um)
        px = float(v.x_um[1] - v.x_um[0])
        model = self._model(rows, cols)  # every plane: no object is cut out along z
        measured = bk.asarray(model.crop(views), np.float32)
        weight = bk.asarray(model.crop(np.asarray(v.view_mask, np.float32)))
        noise = float(start.report.get("tv_noise", float("nan")))
        noise = noise if math.isfinite(noise) else 0.0
        n_data = max(float(bk.xp.sum(weight)), 1.0)
        contrast = float(bk.xp.sum(weight * (measured - 1.0) ** 2)) / n_data  # the views' mean squared contrast
        stop = discrepancy_stop(ms, contrast, noise)
        enough = 0.5 * n_data * noise**2 * stop
        lo, hi = bounds(_sign_of(start), s.settings.tv.dn_max)  # in Δn
        # inside the field stop, and off the region's edge, which is held at the medium
        inside = np.asarray(v.mask[rows, cols], np.float32)[None] * medium_edge(
            rows.stop - rows.start, px, ms.medium_edge_um
        )

        def fit_on(model, fine: bool, where=inside) -> Fit:
            k = ms.refine
            unknowns = Unknowns(1 if fine else k, bk.xp)
            ins = np.repeat(np.repeat(where, k, axis=1), k, axis=2) if fine else where
            voxel = (s.dz_um, px / k, px / k) if fine else (s.dz_um, px, px)
            mu = ms.tv_weight * noise
            return Fit(model, measured, weight, unknowns, lo, hi, bk.asarray(ins), mu, voxel)

        def misfit_map(res) -> np.ndarray:
            """The squared residual per pixel of the region, averaged over the views with data, (ny, nx)."""
            return bk.to_host(bk.xp.sum(res * res, axis=0) / bk.xp.maximum(bk.xp.sum(weight, axis=0), 1.0))

        predicted: dict = {}  # the model's views of the last report, for the rest of the frame

        def report(fit: Fit, model: ViewsMultislice, x, on_views, history, converged):
            """The report of the fit ending at x (on its unknowns' grid; ``on_views``: on the views')."""
            predicted["views"], res = fit.views_and_residual(x)
            sq = float(bk.xp.sum(res * res))
            per_pixel = misfit_map(res)
            objects = fit_objects(
                on_views,
                per_pixel,
                s.z_um,
                v.y_um[rows],
                v.x_um[cols],
                noise=noise,
                alpha_um3_pg=s.settings.refraction_increment_um3_pg,
                stop=stop,
            )
            return {
                **start.report,
                "multislice_iterations_run": len(history["relative_change"]),
                "multislice_converged": converged,
                "multislice_objective_start": history["objective"][0],
                "multislice_objective_final": history["objective"][-1],
                "multislice_residual_rms": math.sqrt(sq / n_data),
                "multislice_residual_over_noise": sq / n_data / noise**2 if noise > 0 else None,
                "multislice_contrast_over_noise": contrast / noise**2 if noise > 0 else None,
                "multislice_stop_over_noise": stop,
                "multislice_roi_px": [rows.start, rows.stop, cols.start, cols.stop],
                "multislice_z_um": [float(model.z_um[0]), float(model.z_um[-1])],
                "multislice_source_points": [model.n_sources, model.n_subsources],
                "multislice_seconds": time.perf_counter() - t0,
                "multislice_device": bk.name,
                "multislice_objects": objects,
            }

        # a start the model explains as it is (a weak object) is kept whole, tails of the missing cone
        # included: cutting them would only lose the mass they carry
        within = enough * (1.0 + WITHIN_STOP_SIGMAS * math.sqrt(2.0 / n_data))  # the stop, within the misfit's scatter
        coarse = fit_on(model, fine=False)
        x0 = coarse.project(bk.asarray(dn[:, rows, cols]))
        r = coarse.residual(x0)
        f0 = 0.5 * float(bk.xp.sum(r * r))
        over_noise = (lambda f: 2.0 * f / n_data / noise**2) if noise > 0 else (lambda f: None)
        starts = {"tv": over_noise(f0)}
        if f0 <= within:
            kept = report(coarse, model, x0, bk.to_host(x0), {"objective": [f0], "relative_change": []}, True)
            kept |= _starts_report(starts, "tv", [], 0.0)
            return Solution(start.phase, kept, {**start.history, "multislice": {"objective": [f0]}}, state=start.state)

        fine = ms.unknowns == "model"  # sub-pixel edges: each view pixel's k x k model samples are free
        unknowns = Unknowns(ms.refine, bk.xp)
        fit = fit_on(model, fine)
        x_start, chosen, beads, best = unknowns.up(x0) if fine else x0, "tv", [], f0
        starts_seconds = 0.0
        if warm is not None and np.shape(warm.phase) == dn.shape:
            # a later frame of a series: the previous frame's answer is a start too (ranked by the
            # misfit; the fit always runs from it: the sample may have moved within the stop)
            xw = coarse.project(bk.asarray(np.asarray(warm.phase, np.float32)[:, rows, cols] * to_dn))
            rw = coarse.residual(xw)
            fw = 0.5 * float(bk.xp.sum(rw * rw))
            starts["previous frame"] = over_noise(fw)
            if fw < best:
                x_start, chosen, best = unknowns.up(xw) if fine else xw, "previous frame", fw
        if ms.sphere_start and noise > 0:
            # the model does not explain the first answer: a second start, the objects fitted as spheres
            # (Chowdhury et al. 2019 start from a first-order answer; a strong bead's lies toward its
            # focus, too weak, where the fit stays trapped; 'tv' may read a small strong bead as weak);
            # a later frame of a series fits its beads from the previous frame's (no scan)
            before = [] if warm is None else warm.report.get("multislice_start_beads", [])
            previous = [Bead.from_dict(b) for b in before]
            t_beads = time.perf_counter()
            candidates, beads = sphere_starts(
                self.setup, views, dn, (rows, cols), model, noise, previous, progress, should_stop
            )
            starts_seconds = time.perf_counter() - t_beads
            for label, spheres in candidates.items():  # ranked by the misfit
                xs = fit.project(spheres if fine else unknowns.down(spheres) / ms.refine**2)
                rs = fit.residual(xs)
                fs = 0.5 * float(bk.xp.sum(rs * rs))
                starts[label] = over_noise(fs)
                if fs < best:
                    x_start, chosen, best = xs, label, fs
            if chosen.startswith("spheres"):
                xs, fs = x_start, best
                # the spheres explain the views: kept as they are; so are the spheres alone (every
                # object of the region a bead the fit vouched for) within the bound of an explained
                # bead: a voxel fit from them explains the model's own error with Δn the sample does
                # not have (the demo's PMMA bead at condenser NA 0.3: 9.2 x the noise for a stop of
                # 6.9, then 60 iterations, 7 minutes, and 1.07 x its mass for the spheres' 1.00), and
                # what they leave unexplained the rest of the frame's 'tv' takes
                alone = chosen == "spheres alone" and over_noise(fs) <= explained_limit(stop)
                if fs <= within or alone:
                    on_views = unknowns.down(xs) / ms.refine**2 if fine else xs
                    dn[:, rows, cols] = bk.to_host(on_views)
                    history = {"objective": [fs], "relative_change": []}
                    kept = report(fit, model, xs, dn[:, rows, cols], history, True)
                    kept |= _starts_report(starts, chosen, beads, starts_seconds)
                    region = (rows, cols)
                    dn, rest = self._with_rest(views, dn, region, predicted["views"], start, progress, should_stop)
                    kept |= rest
                    return Solution(
                        (dn / to_dn).astype(np.float32),
                        kept,
                        {**start.history, "multislice": history},
                        state=start.state,
                    )

        def fitted(fit: Fit, start, label: str):
            return projected_gradient(
                fit,
                start,
                iterations=ms.iterations,
                tolerance=TOLERANCE,
                enough=enough,
                progress=progress,
                should_stop=should_stop,
                label=label,
            )

        result = fitted(fit, x_start, "multislice")
        x = Unknowns(ms.refine, bk.xp).down(result.x) / ms.refine**2 if fine else result.x  # the views' grid
        if ms.support_margin_um > 0 and not (should_stop is not None and should_stop()):
            # a second fit held to the first one's objects (grown by the margin): the Δn the first
            # fit spread elsewhere, at other depths, goes back to the medium unless the data need it
            first_x, history = result.x, result.history
            where = inside * object_support(bk.to_host(x), (s.dz_um, px, px), ms.support_margin_um)
            for _ in range(SUPPORT_ROUNDS):
                fit = fit_on(model, fine, where.astype(np.float32))
                result = fitted(fit, fit.project(result.x), "multislice (objects)")
                history = {k: history[k] + result.history[k] for k in history}
                # where the views are still not explained, an object was held out: free its columns
                misfit = misfit_map(fit.residual(result.x))
                held = unexplained_columns(misfit, noise, stop, px, ms.support_margin_um) & ~where.all(axis=0)
                if not held.any() or (should_stop is not None and should_stop()):
                    break
                where[:, held] = inside[:, held]
                free = bk.asarray(np.repeat(np.repeat(held, ms.refine, 0), ms.refine, 1) if fine else held)
                result.x = bk.xp.where(free[None], first_x, result.x)  # those columns restart from the first fit
            result.history = history
            x = Unknowns(ms.refine, bk.xp).down(result.x) / ms.refine**2 if fine else result.x
        dn[:, rows, cols] = bk.to_host(x)
        out = report(fit, model, result.x, dn[:, rows, cols], result.history, result.converged)
        out |= _starts_report(starts, chosen, beads, starts_seconds)
        if not (should_stop is not None and should_stop()):
            dn, rest = self._with_rest(views, dn, (rows, cols), predicted["views"], start, progress, should_stop)
            out |= rest
        stopped = should_stop is not None and should_stop()
        if not result.converged and not stopped:
            warnings.warn(
                f"the multislice fit did not converge in {result.iterations} iterations: the views are "
                f"{out['multislice_residual_over_noise'] or float('nan'):.1f} x the noise from the model (it stops at "
                f"{stop:.1f}); its Δn may still be off: raise the multislice iterations "
                "(--multislice-iterations, or the run configuration's multislice: iterations)",
                SsdpcWarning,
                stacklevel=2,
            )
        unexplained = [o for o in out["multislice_objects"] if not o["explained"]]
        if unexplained and not stopped:
            where = "; ".join(
                f"({', '.join(f'{c:.1f}' for c in o['centre_um'])}) µm: {o['residual_over_noise']:.1f} x"
                for o in unexplained
            )
            warnings.warn(
                f"the multislice model does not explain the views over {len(unexplained)} object(s), their Δn is "
                f"not to be trusted [{where} the noise; the fit stops at {stop:.1f}]: check the optics (`ssdpc "
                "fit-optics` fits them to a frame of beads) and the calibration, or raise the multislice iterations",
                SsdpcWarning,
                stacklevel=2,
            )
        history = {**start.history, "multislice": result.history}
        return Solution((dn / to_dn).astype(np.float32), out, history, state=start.state)

    def _with_rest(self, views, dn, region, predicted, start: Solution, progress, should_stop):
        """The frame's Δn and the report's keys with the rest of the frame solved
        (:func:`~napari_ssdpc.reconstruction.rest_of_frame.with_rest`; ``dn`` itself when
        ``multislice.rest_of_frame`` is off)."""
        s = self.setup
        if not s.settings.multislice.rest_of_frame:
            return dn, {}
        return with_rest(s, self.tv, views, dn, region, predicted, _sign_of(start), progress, should_stop)

    def _model(self, rows: slice, cols: slice) -> ViewsMultislice:
        """The multislice model of the views on every plane of the output grid and the region (rows, cols):
        built once for a region and kept while the frames of a series need the same (the last two)."""
        s = self.setup
        where = (rows.start, rows.stop, cols.start, cols.stop)
        key = json.dumps([where, s.settings.multislice.to_dict()], sort_keys=True, default=str)
        if key not in self._models:
            while len(self._models) >= 2:
                self._models.pop(next(iter(self._models)))
            self._models[key] = self._build_model(rows, cols)
        return self._models[key]

    def _build_model(self, rows: slice, cols: slice) -> ViewsMultislice:
        s = self.setup
        return s.views.multislice_model(
            s.z_um,
            s.dz_um,
            (rows, cols),
            s.settings.multislice,
            backend=s.backend,
            max_bytes=available_memory(),
        )

    def settings(self) -> dict:
        """The Tikhonov α of the 'tv' start."""
        return self.tv.settings()
