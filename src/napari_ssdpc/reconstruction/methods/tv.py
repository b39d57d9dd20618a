"""The 'tv' method (default): the views' WOTFs inverted with total variation and constraints.

Started from the Tikhonov solution of the same frame (the 'wotf' inverse on the output planes),
or from a given warm start (the previous frame of a series); solved by ADMM (:mod:`..regularised`,
docs/method.md).
"""

from __future__ import annotations

import math
import warnings
import weakref

import numpy as np

from napari_ssdpc.errors import SsdpcWarning
from napari_ssdpc.reconstruction.forward import padded_planes
from napari_ssdpc.reconstruction.methods.base import PhaseMethod, Setup, Solution
from napari_ssdpc.reconstruction.methods.wotf import contrast_of, view_model
from napari_ssdpc.reconstruction.regularised import TvInversion, TvState
from napari_ssdpc.reconstruction.wotf import WotfInversion

__all__ = ["STRONG_PHASE_RAD", "TvMethod"]

#: Beyond this phase through an object (rad, as 'tv' measures it) the first-order model of the views
#: (paper Eqs. 2-4) no longer holds: 'tv' loses mass and trails the object along z. A 9 µm bead of
#: 1.09 rad reads 1.08 rad and keeps its mass (0.98); a 5 µm polystyrene bead of 15.7 rad reads
#: only 1.4 rad (mass 0.12): 'tv' itself saturates (docs/nonlinear.md).
STRONG_PHASE_RAD = 1.2


class TvMethod(PhaseMethod):
    """ADMM with anisotropic TV, sparsity, the sign of Δn, |Δn| ≤ dn_max and the field stop.

    Without a warm start a frame starts from its Tikhonov solution and runs up to ``iterations``;
    a frame of a series warm-started from the previous frame's solution starts from where that
    solve ended (all ADMM variables and the sign 'auto' chose) and runs up to
    ``warm_iterations``, stopping on the same relative change. Such a frame also takes the
    temporal prior ``temporal_weight`` x μ ‖φ − φ_prev‖₁ against the previous frame's phase
    (docs/method.md); the first frame of a series has none."""

    name = "tv"

    def __init__(self, setup: Setup, wotf: WotfInversion, tv: TvInversion):
        self.setup, self.wotf, self.tv = setup, wotf, tv
        # the last frame's solve, for a refinement: (views, weak reference to its warm start or None,
        # tv settings, solution)
        self._last: tuple | None = None

    def _is_last(self, views, warm: Solution | None) -> bool:
        """Whether the last solve had these views, this start and these settings (nothing is
        hashed per frame: the views are kept by reference and compared only when asked)."""
        if self._last is None:
            return False
        last_views, last_warm, settings, _ = self._last
        same_start = warm is None if last_warm is None else last_warm() is warm
        same_views = last_views.shape == np.shape(views) and np.array_equal(last_views, views)
        return same_start and settings == self.setup.settings.tv.to_dict() and same_views

    def solve_or_reuse(self, views, *, warm: Solution | None = None, progress=None, should_stop=None) -> Solution:
        """:meth:`solve`, or this method's last solution when it was of the same views, start and
        settings (a refinement after the 'tv' answer of the same frame: no second solve, no sign probes).

        Parameters
        ----------
        views : ndarray, float32, (K, ny, nx)
        warm : Solution, optional
        progress, should_stop : callable, optional
            As :meth:`solve`.

        Returns
        -------
        Solution
            Its report says ``tv_reused`` when it is the last solve's.
        """
        if self._last is not None and self._is_last(views, warm):
            last = self._last[3]
            return Solution(last.phase, {**last.report, "tv_reused": True}, last.history, last.state, last.method)
        return self.solve(views, warm=warm, progress=progress, should_stop=should_stop)

    @classmethod
    def _build(cls, setup, progress):
        # one model of the views on the z grid padded by about R_z on each side; the Tikhonov
        # inverse of its output planes gives the start
        r_z = float(setup.views.axial_resolution_um)
        zs, planes = padded_planes(setup.z_um, r_z)
        model = view_model(setup, zs, progress)
        wotf = WotfInversion(model.planes(planes), setup.settings.tv.alpha)
        return cls(setup, wotf, TvInversion(model, planes, r_z, mask=setup.views.mask))

    def first_answer(self, views) -> Solution:
        """The Tikhonov inverse this method starts from (the 'wotf' answer on its planes): shown
        while the iterations run.

        Parameters
        ----------
        views : ndarray, float32, (K, ny, nx)

        Returns
        -------
        Solution
            Its report names it (``first_answer``).
        """
        v = self.setup.views
        phase = self._tikhonov(contrast_of(views, v.view_mask))
        return Solution(phase, {"first_answer": "Tikhonov inverse, the start of 'tv'"}, method=self.name)

    def _solve(self, views, stacks, warm, progress, should_stop):
        v, t = self.setup.views, self.setup.settings.tv
        contrast = contrast_of(views, v.view_mask)
        state = None if warm is None else warm.state
        temporal = 0.0
        if isinstance(state, TvState):
            start, iterations = state, min(t.warm_iterations, t.iterations)  # never more than a cold frame
            temporal = t.temporal_weight
        else:
            start = warm.phase if warm is not None else self._tikhonov(contrast)
            iterations = t.iterations
        phi, report = self._phase(contrast, start, t.sign, iterations, temporal, progress, should_stop)
        history = {"tv": {"objective": report.objective, "relative_change": report.relative_change}}
        out = report.to_dict()
        out["tv_phase_through_rad"] = through = float(np.abs(np.asarray(phi).sum(axis=0)).max())
        if self.setup.settings.method == "tv" and through > STRONG_PHASE_RAD and len(self.setup.z_um) > 1:
            warnings.warn(
                f"an object delays the light by {through:.1f} rad (more than {STRONG_PHASE_RAD} rad) and the "
                f"first-order model leaves {report.residual_over_noise:.0f} x the noise unexplained: 'tv' "
                "underestimates such objects and trails them along z; reconstruct with --method multislice",
                SsdpcWarning,
                stacklevel=2,
            )
        solution = Solution(phi, out, history, state=report.state, method=self.name)
        start = None if warm is None else weakref.ref(warm)  # a series' previous frame is not kept alive
        self._last = (views, start, self.setup.settings.tv.to_dict(), solution)
        return solution

    def _tikhonov(self, contrast):
        """The Tikhonov phase a cold solve starts from, (Z, ny, nx) rad, inside the field stop."""
        return self.wotf.phase(contrast) * self.setup.views.mask

    def _phase(self, contrast, start, sign: str, iterations: int, temporal: float, progress, should_stop, label=None):
        """The ADMM solve of the views' contrast with this method's settings (its bounds and λ);
        ``label``: the progress bar's, instead of the solver's."""
        t = self.setup.settings.tv
        return self.tv.phase(
            contrast,
            warm=start,
            sign=sign,
            phi_max=2 * math.pi * self.setup.dz_um * t.dn_max / self.setup.optics.wavelength_um,  # Δn = λφ/(2π dz)
            lam=t.lambda_scale,
            iterations=iterations,
            temporal_weight=temporal,
            progress=None if progress is None else (lambda i, n, lab="TV", *_: progress(i, n, label or lab)),
            should_stop=should_stop,
        )

    def rest(self, views, sign: str, *, progress=None, should_stop=None):
        """The phase of views from which another model took its objects out (the rest of a frame):
        the same solve from its Tikhonov start, with the sign given (no probes), kept by no cache.

        Parameters
        ----------
        views : ndarray, float32, (K, ny, nx)
            Flat-fielded views, 1 where only direct light is left.
        sign : {'denser', 'lighter', 'any'}
            The sign the frame's own solve chose.
        progress, should_stop : callable, optional
            As :meth:`solve`.

        Returns
        -------
        phase : ndarray, float32, (Z, ny, nx)
            rad per slab.
        report : TvReport
        """
        v, t = self.setup.views, self.setup.settings.tv
        contrast = contrast_of(views, v.view_mask)
        start = self._tikhonov(contrast)
        label = "TV of the rest of the frame"
        phi, report = self._phase(contrast, start, sign, t.iterations, 0.0, progress, should_stop, label)
        return np.asarray(phi, np.float32), report

    def settings(self) -> dict:
        """The Tikhonov α of the start."""
        return {"tikhonov_alpha": self.wotf.alpha}
