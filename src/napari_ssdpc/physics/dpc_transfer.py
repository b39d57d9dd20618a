"""DPC operators: the transfer functions of the four halves of paper Eq. 5 and of the two DPC
images of paper Eq. 1, on a z grid, from either model of :mod:`.transfer`.

For DPC = (I1 − I2)/(I1 + I2) the first-order transfer function is
    H_DPC = 2 (I0_2 H_1 − I0_1 H_2) / (I0_1 + I0_2)²,
which is H_1/I0_1 when the halves mirror each other: the phase TF of one half normalised by that
half's own background, not by the full aperture and not doubled (docs/conventions.md).
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.lattice import lenslet_case
from napari_ssdpc.physics.transfer import LensletSetup, paper_transfer_functions
from napari_ssdpc.settings.lenslets import HALVES, PAIRS
from napari_ssdpc.settings.optics import Optics

__all__ = ["WEAK_CONTRAST", "dpc_from_halves", "dpc_transfer_functions"]

#: In-focus peak |H_DPC| below which the phase is too weak to invert (see docs/operators.md).
WEAK_CONTRAST = 0.1


def dpc_transfer_functions(
    optics: Optics, lenslets=None, shape=(145, 145), pixel_um=None, z_um=0.0, model=None, warn=True
) -> dict:
    """Transfer functions of the four halves and of the two DPC images on a z grid.

    Parameters
    ----------
    optics : Optics
    lenslets : list of Lenslet, optional
        Default: every lenslet in the pupil.
    shape : (int, int)
        Output grid (ny, nx).
    pixel_um : float, optional
        Object pixel, µm (default the optics').
    z_um : float or sequence of float
        Defocus, µm.
    model : {'lenslet', 'paper'}
        The detection-split (lenslet) or half-source (paper Eq. 4) model.
    warn : bool
        Warn when the in-focus phase contrast is too weak to invert.

    Returns
    -------
    dict with
      'H_abs', 'H_phase': {half: (ny, nx) or (Z, ny, nx) complex64}, unshifted FFT order,
      'I0': {half: float} (fraction of the condenser light the half collects),
      'dpc_phase', 'dpc_abs': {'ud'|'lr': ...} first-order TFs of (I1 − I2)/(I1 + I2),
      'dpc_offset': {'ud'|'lr': (I0_1 − I0_2)/(I0_1 + I0_2)},
      'contrast': {'ud'|'lr': in-focus peak |H_DPC|}, 'cases': lenslet cases (lenslet model),
      'freq': (fy, fx) cycles/µm, 'z_um', 'model'.
    Warns (SsdpcWarning) when the in-focus phase contrast is too weak to invert.
    """
    model = model or "lenslet"
    if model not in ("lenslet", "paper"):
        raise SsdpcError(f"unknown transfer model '{model}'; use 'lenslet' or 'paper'")
    if not optics.condenser_na > 0:
        raise SsdpcError("condenser_na is 0: a point source gives no DPC; set the condenser NA in the optics file")
    pixel_um = float(pixel_um or optics.object_pixel_um)
    shape = tuple(int(n) for n in shape)
    lenslets = list(nominal_lenslets(optics) if lenslets is None else lenslets)
    zs = np.asarray(z_um, dtype=float)
    out = {
        "model": model,
        "z_um": zs,
        "freq": tuple(sfft.fftfreq(n, pixel_um) for n in shape),
        "H_abs": {},
        "H_phase": {},
        "I0": {},
    }
    if model == "paper":
        for half, (ha, hp, i0) in paper_transfer_functions(optics, shape, pixel_um, zs).items():
            out["H_abs"][half], out["H_phase"][half], out["I0"][half] = ha, hp, i0
        focus = (
            out["H_phase"]
            if _in_focus(zs)
            else {h: v[1] for h, v in paper_transfer_functions(optics, shape, pixel_um, 0.0).items()}
        )
    else:
        setup = LensletSetup(optics, lenslets, shape, pixel_um)
        members = {h: np.array([h in ln.halves for ln in setup.lenslets]) for h in HALVES}
        out["H_abs"], out["H_phase"] = _half_sums(setup, members, zs)
        out["I0"] = {h: float(setup.i0[sel].sum()) for h, sel in members.items()}
        focus = out["H_phase"] if _in_focus(zs) else _half_sums(setup, members, np.asarray(0.0))[1]
        out["cases"] = [lenslet_case(optics, ln) for ln in setup.lenslets]
    out["dpc_phase"], out["dpc_abs"], out["dpc_offset"], out["contrast"] = {}, {}, {}, {}
    for axis, (h1, h2) in PAIRS.items():
        a1, a2 = out["I0"][h1], out["I0"][h2]
        if not a1 + a2 > 0:
            raise SsdpcError(
                f"no direct light reaches the {h1}/{h2} halves; open the condenser or check the lenslet list"
            )
        out["dpc_phase"][axis] = dpc_from_halves(out["H_phase"][h1], out["H_phase"][h2], a1, a2)
        out["dpc_abs"][axis] = dpc_from_halves(out["H_abs"][h1], out["H_abs"][h2], a1, a2)
        out["dpc_offset"][axis] = (a1 - a2) / (a1 + a2)
        out["contrast"][axis] = float(np.abs(dpc_from_halves(focus[h1], focus[h2], a1, a2)).max())
    if warn:
        _warn_weak(optics, out)
    return out


def dpc_from_halves(h1, h2, i0_1, i0_2):
    """First-order transfer function of (I1 − I2)/(I1 + I2) (paper Eq. 1).

    Parameters
    ----------
    h1, h2 : ndarray, complex
        Transfer functions of the two halves.
    i0_1, i0_2 : float
        Their direct-light backgrounds.

    Returns
    -------
    ndarray, complex64
        2 (I0_2 H_1 − I0_1 H_2)/(I0_1 + I0_2)², i.e. H_1/I0_1 for mirror-image halves.
    """
    return (2.0 * (i0_2 * h1 - i0_1 * h2) / (i0_1 + i0_2) ** 2).astype(np.complex64)


def _half_sums(setup: LensletSetup, members: dict, zs, chunk=16):
    """{half: Σ_k H_k} for H_abs and H_phase, in chunks of z (the per-lenslet TFs stay small)."""
    z1 = np.atleast_1d(zs)
    sums = [{h: np.empty((len(z1),) + setup.shape, np.complex64) for h in members} for _ in range(2)]
    for i in range(0, len(z1), chunk):
        bands = setup.band(z1[i : i + chunk])
        for total, band in zip(sums, bands):
            for h, sel in members.items():
                total[h][i : i + chunk] = setup.embed(band[:, sel].sum(axis=1))
    if zs.ndim == 0:
        sums = [{h: v[0] for h, v in total.items()} for total in sums]
    return sums[0], sums[1]


def _in_focus(zs) -> bool:
    return zs.ndim == 0 and float(zs) == 0.0


def _warn_weak(optics: Optics, out: dict) -> None:
    weakest = min(out["contrast"].values())
    if out["model"] == "lenslet" and "straddling" not in out["cases"]:
        warnings.warn(
            f"no lenslet sub-aperture straddles the edge of the source disk (condenser_na {optics.condenser_na}): "
            "in-focus phase contrast is weak; change the condenser NA so that the source edge crosses the "
            "central lenslets",
            SsdpcWarning,
            stacklevel=3,
        )
    elif weakest < WEAK_CONTRAST:
        warnings.warn(
            f"in-focus DPC phase transfer peaks at {weakest:.3f} (< {WEAK_CONTRAST}) for condenser_na "
            f"{optics.condenser_na} (sigma {optics.sigma:.2f}): phase contrast is too weak to invert; "
            "close the condenser aperture",
            SsdpcWarning,
            stacklevel=3,
        )
