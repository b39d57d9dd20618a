"""The interface every phase method implements, and what it is built from and returns."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from napari_ssdpc.backend import Backend
from napari_ssdpc.errors import Cancelled
from napari_ssdpc.reconstruction.measurements import Measurements
from napari_ssdpc.settings.dpc_optics import DpcOptics
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import ReconstructionSettings

__all__ = ["PhaseMethod", "Setup", "Solution"]


@dataclass
class Setup:
    """What a phase method is built from: everything that does not depend on the frame.

    Attributes
    ----------
    optics : Optics or DpcOptics
        The instrument of the front end (a method reads its wavelength).
    settings : ReconstructionSettings
        The method reads its own section (``settings.tv``, ``settings.wotf``, ...).
    views : Measurements
        The front end's views: their grid, masks and direct light, and their models (the light-field
        views of a calibration, :class:`~napari_ssdpc.reconstruction.contrast.ViewContrast`).
    z_um : ndarray, (Z,)
        The output planes, µm.
    backend : Backend
        NumPy on the CPU or CuPy on a GPU.
    """

    optics: Optics | DpcOptics
    settings: ReconstructionSettings
    views: Measurements
    z_um: np.ndarray
    backend: Backend

    @property
    def dz_um(self) -> float:
        """Slab thickness, µm."""
        return float(self.settings.dz_um)


@dataclass
class Solution:
    """One frame's phase and what the method did.

    Attributes
    ----------
    phase : ndarray, float32, (Z, ny, nx)
        Phase per slab, rad.
    report : dict
        Plain numbers for the result's metadata (iterations, objective, ...).
    history : dict
        Convergence curves ({name: list of float}).
    state : object
        What a warm start of the next frame reuses (the phase, solver variables).
    method : str
        The method that solved it.
    """

    phase: np.ndarray
    report: dict = field(default_factory=dict)
    history: dict = field(default_factory=dict)
    state: Any = None
    method: str = ""


class PhaseMethod(ABC):
    """A phase method: built once, then :meth:`solve` per frame.

    Subclasses set :attr:`name` (their key in :data:`~napari_ssdpc.reconstruction.methods.METHODS`)
    and :attr:`uses_stacks` (whether they take their phase from the directional stacks), and
    implement ``_build(cls, setup, progress)`` (a classmethod that returns the built method) and
    ``_solve(self, views, stacks, warm, progress, should_stop)`` (a :class:`Solution`).
    """

    name: ClassVar[str]
    uses_stacks: ClassVar[bool] = False
    #: The method whose answer this one refines (built once and shared: :meth:`on`), or None.
    starts_from: ClassVar[str | None] = None

    @classmethod
    def build(cls, setup: Setup, progress=None) -> PhaseMethod:
        """Build the method's operators.

        Parameters
        ----------
        setup : Setup
        progress : callable, optional
            ``progress(done, total, label)`` while the operators are built.

        Returns
        -------
        PhaseMethod
        """
        return cls._build(setup, progress)

    def solve(self, views, stacks=None, *, warm: Solution | None = None, progress=None, should_stop=None) -> Solution:
        """The phase of one frame.

        Parameters
        ----------
        views : ndarray, float32, (K, ny, nx)
            Flat-fielded views (1 = direct light), 0 where a view holds no data.
        stacks : Stacks, optional
            The frame's directional stacks (methods with :attr:`uses_stacks`).
        warm : Solution, optional
            A solution to start from (the previous frame's); iterative methods use it.
        progress : callable, optional
            ``progress(done, total, label)`` per iteration.
        should_stop : callable, optional
            Checked every iteration; True stops with :class:`~napari_ssdpc.errors.Cancelled`.

        Returns
        -------
        Solution
            Phase per slab (Z, ny, nx), float32 rad.
        """
        if self.uses_stacks and stacks is None:
            raise ValueError(f"the '{self.name}' method takes its phase from the directional stacks")
        sol = self._solve(views, stacks, warm, progress, should_stop)
        if should_stop is not None and should_stop():
            raise Cancelled("reconstruction cancelled")
        sol.phase = np.asarray(sol.phase, np.float32)
        sol.method = self.name
        return sol

    def first_answer(self, views) -> Solution | None:
        """A quick first answer of the frame, to show while :meth:`solve` works (an iterative
        method's start; a refinement's, that of the method it refines); None where the method has
        none quicker than its answer.

        Parameters
        ----------
        views : ndarray, float32, (K, ny, nx)

        Returns
        -------
        Solution or None
        """
        return None if self.start is None else self.start.first_answer(views)

    @classmethod
    def on(cls, start: PhaseMethod) -> PhaseMethod:
        """This method built on an already built ``start`` method (its :attr:`starts_from`), sharing
        its operators: switching from 'tv' to its refinement rebuilds nothing.

        Parameters
        ----------
        start : PhaseMethod
            A built method of the kind :attr:`starts_from` names.

        Returns
        -------
        PhaseMethod
        """
        raise NotImplementedError(f"the '{cls.name}' method does not start from another method")

    @property
    def start(self) -> PhaseMethod | None:
        """The built method this one refines (None for a method of its own)."""
        return None

    @classmethod
    @abstractmethod
    def _build(cls, setup: Setup, progress) -> PhaseMethod: ...

    @abstractmethod
    def _solve(self, views, stacks, warm: Solution | None, progress, should_stop) -> Solution: ...

    def settings(self) -> dict:
        """The settings this method solves with, for the output metadata."""
        return {}
