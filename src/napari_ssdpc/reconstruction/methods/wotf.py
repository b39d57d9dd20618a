"""The 'wotf' method: 3D Tikhonov inversion of all views' weak-object transfer functions."""

from __future__ import annotations

import numpy as np

from napari_ssdpc.reconstruction.forward import ViewModel
from napari_ssdpc.reconstruction.methods.base import PhaseMethod, Setup, Solution
from napari_ssdpc.reconstruction.wotf import WotfInversion

__all__ = ["WotfMethod", "contrast_of", "view_model"]


def view_model(setup: Setup, z_um, progress=None) -> ViewModel:
    """The views' model (paper Eqs. 2-4) on the planes ``z_um``.

    Parameters
    ----------
    setup : Setup
    z_um : ndarray, (Z,)
        Planes, µm.
    progress : callable, optional

    Returns
    -------
    ViewModel
    """
    return setup.views.linear_model(z_um, backend=setup.backend, progress=progress)


def contrast_of(views, view_mask) -> np.ndarray:
    """I_k / I0_k − 1 of every view, 0 where it holds no data.

    Parameters
    ----------
    views : ndarray, float32, (K, ny, nx)
    view_mask : ndarray of bool, (K, ny, nx)

    Returns
    -------
    ndarray, (K, ny, nx)
    """
    return np.where(view_mask, views - 1.0, 0.0)


class WotfMethod(PhaseMethod):
    """Linear: φ̂(u) = Aᴴ(AAᴴ + αI)⁻¹ ĉ(u) per lateral frequency (:mod:`..wotf`); a warm start
    changes nothing."""

    name = "wotf"

    def __init__(self, setup: Setup, inversion: WotfInversion):
        self.setup, self.inversion = setup, inversion

    @classmethod
    def _build(cls, setup, progress):
        # the Tikhonov inverse on the output planes
        return cls(setup, WotfInversion(view_model(setup, setup.z_um, progress), setup.settings.wotf.alpha))

    def _solve(self, views, stacks, warm, progress, should_stop):
        v = self.setup.views
        return Solution(self.inversion.phase(contrast_of(views, v.view_mask)) * v.mask)

    def settings(self) -> dict:
        """The Tikhonov α."""
        return {"tikhonov_alpha": self.inversion.alpha}
