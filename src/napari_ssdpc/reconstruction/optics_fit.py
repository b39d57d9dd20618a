"""Fit the instrument to the user's own frames: one entry for `ssdpc fit-optics` and napari.

The flat frame gives the condenser (its NA and centre, :mod:`.condenser_fit`), written into a copy of
the calibration that every reconstruction then uses; the white frame gives each view's focus
(:mod:`~napari_ssdpc.calibration.view_focus`), reported and noticed (docs/aberrations.md).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.calibration.view_focus import FocusFit, fit_view_focus
from napari_ssdpc.reconstruction.checks import check_optics_match
from napari_ssdpc.reconstruction.condenser_fit import CondenserFit, fit_condenser
from napari_ssdpc.reconstruction.contrast import ViewContrast
from napari_ssdpc.settings.optics import Optics

__all__ = ["OpticsFit", "fit_optics"]


@dataclass(frozen=True)
class OpticsFit:
    """What the frames say: the calibration with the fitted optics, and each part's fit.

    Attributes
    ----------
    calibration : Calibration
        A copy of the calibration with the fitted condenser in its optics and ``optics_fit``.
    condenser : CondenserFit
    focus : FocusFit or None
        Each view's focus (None without a white frame).
    """

    calibration: Calibration
    condenser: CondenserFit
    focus: FocusFit | None

    def report(self) -> list[str]:
        """Every fitted term with its uncertainty, the misfits, and what to do about blurred views."""
        lines = self.condenser.report()
        if self.focus is not None:
            lines += self.focus.report()
            if self.focus.blurred:
                lines.append(self.focus.notice())
        return [*lines, self.calibration.optics.aberrations.summary()]


def fit_optics(cal: Calibration, flat, optics: Optics | None = None, white=None, progress=None) -> OpticsFit:
    """Fit the condenser to a flat frame (and measure the views' focus on a white frame).

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
        ``progress(done, total)`` while the views' focus is measured.

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
    focus = None if white is None else fit_view_focus(white, cal, fitted.optics, progress)
    return OpticsFit(fitted, condenser, focus)
