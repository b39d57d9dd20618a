"""Fit the instrument to the user's own frames: one entry for `ssdpc fit-optics` and napari.

The flat frame gives the condenser (its NA and centre, :mod:`.condenser_fit`), written into a copy of
the calibration that every reconstruction then uses; the white frame gives each view's |focus|
(:mod:`~napari_ssdpc.calibration.view_focus`), reported and noticed; a frame of beads gives the
objective's aberration and each view's defocus with its sign (:mod:`.pupil_fit`), written into the
calibration's optics (docs/aberrations.md).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.calibration.view_focus import FocusFit, fit_view_focus
from napari_ssdpc.reconstruction.checks import check_optics_match
from napari_ssdpc.reconstruction.condenser_fit import CondenserFit, fit_condenser
from napari_ssdpc.reconstruction.contrast import ViewContrast
from napari_ssdpc.reconstruction.pupil_fit import PupilFit, fit_pupil
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics

__all__ = ["BeadFrame", "OpticsFit", "fit_optics"]


@dataclass(frozen=True)
class BeadFrame:
    """A frame of beads to fit the pupil to.

    Attributes
    ----------
    config : RunConfig
        The volume the beads lie in and the multislice model's sampling; its optics' medium index is
        the beads' medium.
    frame : ndarray, (H, W)
        The raw frame, camera units.
    bead_ri : float or None
        The beads' index, when known.
    name : str
        The frame's name in messages.
    """

    config: RunConfig
    frame: Any
    bead_ri: float | None = None
    name: str = "bead frame"


@dataclass(frozen=True)
class OpticsFit:
    """What the frames say: the calibration with the fitted optics, and each part's fit.

    Attributes
    ----------
    calibration : Calibration
        A copy of the calibration with the fitted terms in its optics and ``optics_fit``.
    condenser : CondenserFit
    focus : FocusFit or None
        Each view's |focus| (None without a white frame).
    pupil : PupilFit or None
        The objective's terms and the views' defocus fitted to beads (None without a bead frame).
    """

    calibration: Calibration
    condenser: CondenserFit
    focus: FocusFit | None
    pupil: PupilFit | None = None

    def report(self) -> list[str]:
        """Every fitted term with its uncertainty, the misfits, and what to do about blurred views."""
        lines = self.condenser.report()
        if self.focus is not None:
            lines += self.focus.report()
            if self.focus.blurred and self.pupil is None:
                lines.append(self.focus.notice())
        if self.pupil is not None:
            lines += self.pupil.report()
        return [*lines, self.calibration.optics.aberrations.summary()]


def fit_optics(
    cal: Calibration,
    flat,
    optics: Optics | None = None,
    white=None,
    progress=None,
    beads: BeadFrame | None = None,
    should_stop=None,
) -> OpticsFit:
    """Fit the condenser to a flat frame (the views' |focus| to a white frame, the pupil to beads).

    Parameters
    ----------
    cal : Calibration
    flat : ndarray, (H, W)
        Flat frame (no sample, the raw frames' condenser setting), camera units.
    optics : Optics, optional
        The optics given; default the calibration's.
    white : ndarray, (H, W), optional
        The white frame (condenser open): each view's focus from its EI rims.
    progress : callable, optional
        ``progress(done, total, label)`` while the views' focus is measured and the pupil fitted.
    beads : BeadFrame, optional
        A frame of beads: the objective's aberration and the views' defocus are fitted to it.
    should_stop : callable, optional
        True stops the fit of the pupil (:class:`~napari_ssdpc.errors.Cancelled`).

    Returns
    -------
    OpticsFit

    Raises
    ------
    SsdpcError
        Optics of another instrument, a frame of another shape, or frames that do not determine
        the terms (one line each, from the fits).
    """
    optics = cal.optics if optics is None else optics
    check_optics_match(optics, cal, "--optics")
    levels, _ = ViewContrast(optics, cal).lenslet_levels(cal.check_frame(flat, "flat frame"), "flat frame")
    condenser = fit_condenser(levels, cal.lenslets, optics)
    fitted = dataclasses.replace(
        cal, optics=condenser.optics(optics), optics_fit={**cal.optics_fit, "condenser": condenser.to_dict(optics)}
    )
    focus = None
    if white is not None:
        focus = fit_view_focus(white, cal, fitted.optics, progress and (lambda d, t: progress(d, t, "views' focus")))
    if beads is None:
        return OpticsFit(fitted, condenser, focus)
    pupil = fit_pupil(
        beads.config, fitted, flat, beads.frame, focus=focus, bead_ri=beads.bead_ri, name=beads.name,
        progress=progress, should_stop=should_stop,
    )  # fmt: skip
    aberrations = pupil.aberrations(fitted.optics.aberrations).to_dict()
    # the pupil holds for samples in the beads' medium
    optics_with = fitted.optics.replace(medium_index=pupil.medium_index, aberrations=aberrations)
    fitted = dataclasses.replace(fitted, optics=optics_with, optics_fit={**fitted.optics_fit, "pupil": pupil.to_dict()})
    return OpticsFit(fitted, condenser, focus, pupil)
