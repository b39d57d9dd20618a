"""The ssDPC reconstruction: one raw frame in, a 3D refractive-index volume out.

Per frame (paper §2 and §3.2, docs/conventions.md):
1. the frame is checked, its views extracted once and flat-fielded (:mod:`.contrast`);
2. where the method or the outputs ask for them, the directional stacks (Eq. 5-6), DPC (Eq. 1)
   and absorption (:mod:`.stacks`);
3. the phase per slab by the chosen method (:mod:`.methods`: 'tv' by default, 'wotf', 'rl';
   docs/validation.md compares them), optionally from a warm start;
4. Δn = λφ/(2π dz) and n = n_medium + Δn.

Everything that does not depend on the frame is built once, from one
:class:`~napari_ssdpc.settings.config.RunConfig`: each part reads its own section.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from napari_ssdpc.backend import get_backend
from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics.design import design
from napari_ssdpc.reconstruction import checks, memory
from napari_ssdpc.reconstruction.contrast import ViewContrast
from napari_ssdpc.reconstruction.dpc import phase_to_delta_n
from napari_ssdpc.reconstruction.frame_result import Result, z_grid
from napari_ssdpc.reconstruction.instrument_notices import instrument_notices
from napari_ssdpc.reconstruction.methods import method_class
from napari_ssdpc.reconstruction.methods.base import PhaseMethod, Setup, Solution
from napari_ssdpc.reconstruction.stacks import DirectionalStacks
from napari_ssdpc.settings.config import RunConfig

__all__ = ["Reconstructor"]


class Reconstructor:
    """Everything computed once per run configuration, calibration and flat: the checks, the lit
    lenslets and flat field, the directional stacks' operators (when asked for) and the phase
    method's operators; then :meth:`reconstruct` frame after frame.

    Parameters
    ----------
    config : RunConfig
        The optics, the reconstruction settings (the method reads its own section) and the
        outputs (whether the directional stacks are needed).
    calibration : Calibration
        Of the camera that recorded the frames.
    flat : ndarray, (H, W), optional
        Flat frame at the raw frames' condenser NA, camera units.
    dark : float, optional
        Dark offset, camera units; None: estimated on every frame.
    stacks : bool
        Compute the directional stacks even where no output needs them.
    progress : callable, optional
        ``progress(done, total, label)`` while the operators are built.
    min_light : float
        A lenslet counts as lit at this fraction of the brightest's direct light.
    check_memory : bool
        Refuse settings whose operators do not fit in the free memory.
    backend : Backend, optional
        An array backend instead of the one ``reconstruction.device`` names.
    method : type of PhaseMethod, optional
        A phase method to use instead of the registered one ``reconstruction.method`` names (to
        try a method before it is registered; docs/architecture.md).
    """

    def __init__(
        self,
        config: RunConfig,
        calibration: Calibration,
        *,
        flat=None,
        dark=None,
        stacks: bool = False,
        progress=None,
        min_light: float = 0.05,
        check_memory: bool = True,
        backend=None,
        method: type[PhaseMethod] | None = None,
    ):
        if not isinstance(config, RunConfig):
            raise SsdpcError(
                f"Reconstructor takes a RunConfig (optics, reconstruction, outputs), got {type(config).__name__}; "
                "use RunConfig.of(optics, ...)"
            )
        # the backend first: no operators are built for a device that is not there
        self.backend = get_backend(config.reconstruction.device) if backend is None else backend
        if not isinstance(calibration, Calibration):
            raise SsdpcError(
                f"Reconstructor takes a Calibration, got {type(calibration).__name__}; "
                "read one with Calibration.from_json(path) or make one with calibrate(white, optics)"
            )
        _check_arguments(min_light=min_light, progress=progress, method=method)
        t0 = time.perf_counter()
        self.config, self.calibration = config, calibration
        self.optics = optics = checks.optics_in_use(config.optics, calibration, "optics")
        settings = config.reconstruction
        method = method_class(settings.method) if method is None else method
        with_stacks = bool(stacks) or config.outputs.needs_stacks or method.uses_stacks
        if check_memory:
            memory.check_memory(optics, calibration, settings, with_stacks)
        self.dz = float(settings.dz_um)
        self.z_um = z_grid(settings.z_min_um, settings.z_max_um, self.dz)
        self._check_depth_of_field()
        self.views = v = ViewContrast(optics, calibration, flat, dark, min_light)
        #: Signs on the white and flat frames of an instrument unlike the optics in use, said on every frame.
        self.notices = instrument_notices(calibration, optics, v.flat_levels)
        self.stacks = None
        if with_stacks:
            self.stacks = DirectionalStacks(
                optics,
                v.lenslets,
                v.halves,
                v.view_mask,
                v.mask,
                v.pixel_um,
                self.z_um,
                settings.rl,
                self.backend,
                progress,
            )
        self._setup = Setup(optics, settings, v, self.z_um, self.backend)
        self.method = method.build(self._setup, progress)
        self.build_seconds = time.perf_counter() - t0

    def adopt(self, config: RunConfig) -> bool:
        """Take ``config`` for the next frames if its operators are these: only runtime keys differ, or
        the method becomes the refinement of this one ('tv' -> 'multislice', whose next solve of the
        frame 'tv' just solved reuses that answer) or the method this one refines.

        Parameters
        ----------
        config : RunConfig

        Returns
        -------
        bool
            False where the operators would differ: build a new Reconstructor.
        """
        new, old = config.reconstruction.operator_key(), self.config.reconstruction.operator_key()
        method = self._method_for(config.reconstruction.method)
        same = config.optics in (self.config.optics, self.optics) and {**new, "method": ""} == {**old, "method": ""}
        if not same or method is None or (config.outputs.needs_stacks and self.stacks is None):
            return False
        self.config = config
        self._setup.settings = config.reconstruction
        self.method = method
        if self.stacks is not None:
            self.stacks.settings = config.reconstruction.rl
        return True

    def _method_for(self, name: str) -> PhaseMethod | None:
        """The built method ``name`` from this one's operators: itself, the method it refines
        ('multislice' -> 'tv'), or its refinement ('tv' -> 'multislice'); None: build anew."""
        m = self.method
        if m.name == name:
            return m
        if m.start is not None and m.start.name == name:
            return m.start
        cls = method_class(name)
        return cls.on(m) if cls.starts_from == m.name else None

    # the views' geometry, for writers and widgets
    @property
    def lit(self) -> np.ndarray:
        """Indices of the lit lenslets in the calibration."""
        return self.views.lit

    @property
    def lenslets(self) -> list:
        """The lit lenslets, in the order of the views."""
        return self.views.lenslets

    @property
    def mask(self) -> np.ndarray:
        """The field stop on the view grid, (ny, nx) bool."""
        return self.views.mask

    @property
    def pixel_um(self) -> float:
        """Object-space pixel, µm."""
        return self.views.pixel_um

    @property
    def y_um(self) -> np.ndarray:
        """(ny,) µm from the optical axis."""
        return self.views.y_um

    @property
    def x_um(self) -> np.ndarray:
        """(nx,) µm from the optical axis."""
        return self.views.x_um

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

    # ---------------------------------------------------------- per frame
    def reconstruct(
        self, frame, *, warm: Solution | None = None, progress=None, should_stop=None, name="frame"
    ) -> Result:
        """The RI volume of one raw frame (and whatever else the outputs ask for).

        Parameters
        ----------
        frame : array_like, (H, W)
            Raw frame, camera units.
        warm : Solution, optional
            The previous frame's solution (``result.solution``): iterative methods start there.
        progress : callable, optional
            ``progress(done, total, label)`` per iteration.
        should_stop : callable, optional
            Checked every iteration; True stops with :class:`~napari_ssdpc.errors.Cancelled`.
        name : str
            The frame's name in error messages.

        Returns
        -------
        Result
            RI, Δn and phase volumes (z, y, x) on the µm grid, the 2D maps, the settings and timings.

        Raises
        ------
        SsdpcError
            The frame does not fit the calibration or the flat, or the result is not finite or
            beyond any sample.
        """
        _check_arguments(warm=warm, progress=progress, should_stop=should_stop)
        t0 = time.perf_counter()
        views, exposure = self.views.measure(frame, name)
        t1 = time.perf_counter()
        stacks = None if self.stacks is None else self.stacks(views, progress=progress, should_stop=should_stop)
        t2 = time.perf_counter()
        sol = self.method.solve(views, stacks, warm=warm, progress=progress, should_stop=should_stop)
        timings = {"preprocess_s": t1 - t0, "rl_s": t2 - t1}
        return self._result(sol, stacks, exposure, name, timings, t2)

    def first_answer(self, frame, *, name="frame") -> Result | None:
        """A quick first answer of one raw frame, to show while :meth:`reconstruct` works on it (the
        Tikhonov inverse 'tv' starts from: seconds, where 'tv' takes a minute); None where the
        method has none quicker than its answer.

        Parameters
        ----------
        frame : array_like, (H, W)
            Raw frame, camera units.
        name : str
            The frame's name in error messages.

        Returns
        -------
        Result or None
            As :meth:`reconstruct`; its settings say ``first_answer``.
        """
        t0 = time.perf_counter()
        views, exposure = self.views.measure(frame, name)
        t1 = time.perf_counter()
        sol = self.method.first_answer(views)
        if sol is None:
            return None
        sol.phase = np.asarray(sol.phase, np.float32)
        return self._result(sol, None, exposure, name, {"preprocess_s": t1 - t0, "rl_s": 0.0}, t1)

    def _result(self, sol: Solution, stacks, exposure: float, name: str, timings: dict, started: float) -> Result:
        """The Result of a method's solution (checked: finite, within any sample)."""
        phase = np.asarray(sol.phase, np.float32)
        dn = phase_to_delta_n(phase, self.optics.wavelength_um, self.dz)
        checks.check_result(dn, self.optics, name=f"volume of {name}")
        for note in self.notices:
            warnings.warn(note, SsdpcWarning, stacklevel=3)
        t3 = time.perf_counter()
        history = {**({} if stacks is None else stacks.history), **sol.history}
        return Result(
            ri=np.float32(self.optics.medium_index) + dn,  # n = n_medium + Δn
            delta_n=dn,
            phase=phase,
            absorption=None if stacks is None else stacks.absorption,
            dpc={} if stacks is None else stacks.dpc,
            stacks={} if stacks is None else stacks.stacks,
            z_um=self.z_um.copy(),
            y_um=self.y_um.copy(),
            x_um=self.x_um.copy(),
            convergence=history,
            timings={**timings, "phase_s": t3 - started},
            settings={**self.settings(), **sol.report, "exposure_ratio": exposure, "instrument_notices": self.notices},
            solution=sol,
        )

    def settings(self) -> dict:
        """The settings this reconstructor solves with, for the output metadata: the reconstruction
        settings (every section), the z grid as built, the medium index RI is relative to, the
        method's own numbers, the lit lenslets."""
        return {
            **self.config.reconstruction.to_dict(),
            "method": self.method.name,
            "z_min_um": float(self.z_um[0]),
            "z_max_um": float(self.z_um[-1]),
            "dz_um": self.dz,
            "medium_index": float(self.optics.medium_index),  # RI = medium_index + Δn
            "condenser_na_seen": self.views.condenser_na_seen,  # measured on the flat
            **self.method.settings(),
            "lenslets_used": [[ln.row, ln.col] for ln in self.lenslets],
        }


def _check_arguments(**given) -> None:
    """One-line errors for Python API arguments of the wrong kind (the CLI and napari pass them right)."""
    for key, value in given.items():
        if value is None:
            continue
        if key == "min_light":
            ok = isinstance(value, (int, float, np.number)) and not isinstance(value, bool) and 0 < value < 1
            want = "a fraction of the brightest lenslet's light, 0 to 1 (default 0.05)"
        elif key == "warm":
            ok, want = isinstance(value, Solution), "the previous frame's result.solution, or None"
        elif key == "method":
            ok = isinstance(value, type) and issubclass(value, PhaseMethod)
            want = "a PhaseMethod class (docs/architecture.md), or None for reconstruction.method"
        else:
            ok, want = callable(value), "a function, or None"
        if not ok:
            raise SsdpcError(f"{key} = {value!r:.60}: give {want}")
