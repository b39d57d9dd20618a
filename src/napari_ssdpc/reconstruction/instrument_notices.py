"""Signs on the white and flat frames that the instrument is not the optics the operators are built from.

Every operator comes from the optics in use (docs/aberrations.md). Where the user's own frames show
the instrument differs, the numbers move a long way while the residual over noise stays flat, so
each sign is said on every frame reconstructed (a warning and the result's metadata), naming
`ssdpc fit-optics`, which measures what differs:

- the views out of focus: the white frame's elemental-image rims are blurred
  (:func:`~napari_ssdpc.calibration.view_focus.rim_defocus`, measured when the calibration was made)
  and the optics give no lenslet a defocus;
- the condenser off the optics' centre: the flat's lenslets are lit as by a condenser disk off axis
  (:func:`~napari_ssdpc.reconstruction.condenser_fit.fit_condenser`; its NA is checked by
  :mod:`.consistency`).
"""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.calibration.view_focus import rims_notice, rims_unmodelled
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.condenser_fit import fit_condenser

__all__ = ["OFF_AXIS_NA", "condenser_notice", "instrument_notices"]

#: A condenser centre this far from the optics' (NA), and beyond 4 of its standard uncertainties,
#: is reported: simulated flats of a centred condenser read at most 0.0007 off axis, one 0.01 off
#: axis 0.0107-0.0109 (σ 0.0002-0.0003).
OFF_AXIS_NA = 0.005


def condenser_notice(levels, lenslets, optics) -> str | None:
    """One line when the flat's lenslets are lit by a condenser disk off the optics' centre.

    Parameters
    ----------
    levels : ndarray, (K,)
        Every lenslet's light above the dark level on the flat, camera units.
    lenslets : list of Lenslet
        The calibration's lenslets, in the same order.
    optics : Optics
        The optics in use (their condenser NA and centre).

    Returns
    -------
    str or None
        None where the centre agrees, or where the flat does not determine it (the condenser open,
        too few lenslets).
    """
    try:
        fit = fit_condenser(levels, lenslets, optics)
    except SsdpcError:
        return None
    off = np.subtract(fit.offset_na, optics.aberrations.condenser_offset_na)
    if math.hypot(*off) <= max(OFF_AXIS_NA, 4 * math.hypot(*fit.offset_sigma)):
        return None
    (cx, cy), (ox, oy) = fit.offset_na, optics.aberrations.condenser_offset_na
    return (
        f"flat frame: its lenslets are lit as by a condenser disk centred at ({cx:+.3f}, {cy:+.3f}) NA (x, y), the "
        f"optics put it at ({ox:+.3f}, {oy:+.3f}): each view's direct light and transfer function follow the disk; "
        "centre the condenser (Köhler) and record the flat again, or measure its NA and centre with `ssdpc "
        "fit-optics --calibration CAL --flat FLAT -o FITTED.json`"
    )


def instrument_notices(calibration, optics, flat_levels=None) -> list[str]:
    """What the calibration's white frame and the flat show of an instrument unlike ``optics``.

    Parameters
    ----------
    calibration : Calibration
        Its ``rim_defocus_waves`` (None where its frame was not a white frame).
    optics : Optics
        The optics in use.
    flat_levels : ndarray, (K,), optional
        The flat's lenslet levels (none without a flat).

    Returns
    -------
    list of str
        One line per sign, each naming `ssdpc fit-optics`; empty where nothing shows.
    """
    notes: list[str | None] = []
    d = calibration.rim_defocus_waves
    if d is not None and rims_unmodelled(d, optics):
        notes.append(rims_notice(d, "the calibration's white frame"))
    if flat_levels is not None:
        notes.append(condenser_notice(flat_levels, calibration.lenslets, optics))
    return [n for n in notes if n]
