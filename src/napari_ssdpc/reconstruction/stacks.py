"""The paper's directional stacks: Richardson-Lucy per half (Eq. 5-6), DPC (Eq. 1), absorption.

The views of the up, down, left and right halves are each deconvolved by multi-view
Richardson-Lucy with the wave-optics PSF (Eq. 6) into an intensity stack I_κ(z); the DPC stacks
(Eq. 1) have every slice normalised by the z-summed background of the pair, so that a slice holds
only its own contrast; the absorption comes from the sum of the four stacks. The 'rl' method
takes its phase from the DPC stacks; any method can add them to its outputs.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.errors import Cancelled, SsdpcWarning
from napari_ssdpc.physics import dpc_transfer, transfer
from napari_ssdpc.physics.psf import LensletPSF
from napari_ssdpc.physics.pupil import Pupil
from napari_ssdpc.reconstruction.deconvolution import Band, MultiViewRL
from napari_ssdpc.reconstruction.dpc import dpc_image
from napari_ssdpc.settings.lenslets import HALVES, PAIRS
from napari_ssdpc.settings.reconstruction import RlSettings

__all__ = ["DirectionalStacks", "Stacks"]


@dataclass
class Stacks:
    """One frame's directional stacks.

    Attributes
    ----------
    stacks : dict of str to ndarray
        {half: (Z, h, w)} Richardson-Lucy intensity stacks.
    dpc : dict of str to ndarray
        {'ud', 'lr'}: (Z, h, w) DPC stacks (Eq. 1).
    absorption : ndarray, float32, (Z, h, w)
        μ per slab.
    history : dict
        {half: relative change per iteration}.
    h_dpc : dict
        {'ud', 'lr'}: the in-focus DPC phase transfer functions (ny, nx), unshifted.
    """

    stacks: dict
    dpc: dict
    absorption: np.ndarray
    history: dict
    h_dpc: dict


class DirectionalStacks:
    """The PSF operators of each half, built once per optics, lenslets and z grid.

    Parameters
    ----------
    optics : Optics
    lenslets : list of Lenslet
        The lit lenslets.
    halves : dict of str to list of int
        Members of each half (indices into ``lenslets``).
    view_mask : ndarray of bool, (K, h, w)
        Where each view holds data.
    mask : ndarray of bool, (h, w)
        The field stop.
    pixel_um : float
        Object-space pixel, µm.
    z_um : ndarray, (Z,)
        Planes, µm.
    settings : RlSettings
        Iterations and the DPC transfer model.
    backend : Backend
    progress : callable, optional
        ``progress(done, total, label)`` per plane while the operators are built.
    """

    def __init__(
        self, optics, lenslets, halves, view_mask, mask, pixel_um, z_um, settings: RlSettings, backend, progress=None
    ):
        self.halves, self.mask, self.settings = halves, mask, settings
        shape = mask.shape
        self.psf = LensletPSF(optics, lenslets, shape, pixel_um, z_max_um=float(np.max(np.abs(z_um))))
        shift = float(np.abs(self.psf.shift_um(np.max(np.abs(z_um)))).max()) / pixel_um  # the largest parallax, px
        n = [sfft.next_fast_len(int(s + self.psf.support_px + 2 * math.ceil(shift)), real=True) for s in shape]
        self.fft_shape = tuple(n)
        # the OTFs vanish outside |f| ≤ 2ρ (autocorrelation of the sub-aperture; the widest lenslet's
        # own ρ): keep that band (+2 frequency steps for the soft pupil edge); what lies outside is
        # below 4e-4 of the DC
        self.band = Band.disk(self.fft_shape, 2 * Pupil.of(optics).rho_max * pixel_um + 2.0 / min(n))
        otf = {h: np.empty((len(m), len(z_um)) + self.band.box_shape, np.complex64) for h, m in halves.items()}
        for i, z in enumerate(z_um):
            full = self.band.take(self.psf.otf(float(z), self.fft_shape))
            for h, m in halves.items():
                otf[h][:, i] = full[m]
            if progress is not None:
                progress(i + 1, len(z_um), "PSF")
        self.psf.clear_cache()
        shared: dict = {}  # the halves run one after the other: they share their FFT scratch buffers
        self.rl = {
            h: MultiViewRL(otf.pop(h), shape, view_mask[m], band=self.band, backend=backend, workspace=shared)
            for h, m in halves.items()
        }
        self.h_dpc = self._dpc_transfer(optics, lenslets, shape, pixel_um)

    def _dpc_transfer(self, optics, lenslets, shape, pixel_um) -> dict:
        """DPC transfer functions (in focus) of each axis, on the view grid."""
        if self.settings.model == "lenslet":
            _, h_phase, i0 = transfer.lenslet_transfer_functions(optics, lenslets, shape, pixel_um)
            norm = {h: np.mean([h_phase[k] / i0[k] for k in m], axis=0) for h, m in self.halves.items()}
            h_dpc = {ax: (0.5 * (norm[a] - norm[b])).astype(np.complex64) for ax, (a, b) in PAIRS.items()}
        else:
            tf = dpc_transfer.dpc_transfer_functions(optics, lenslets, shape, pixel_um, 0.0, model="paper", warn=False)
            h_dpc = {ax: tf["dpc_phase"][ax] for ax in PAIRS}
        peak = min(float(np.abs(h).max()) for h in h_dpc.values())
        if peak < dpc_transfer.WEAK_CONTRAST:
            warnings.warn(
                f"in-focus DPC phase transfer peaks at {peak:.3f}: phase contrast is too weak to "
                "invert; close the condenser aperture",
                SsdpcWarning,
                stacklevel=4,
            )
        return h_dpc

    def __call__(self, views, progress=None, should_stop=None) -> Stacks:
        """The directional, DPC and absorption stacks of one frame's views.

        Parameters
        ----------
        views : ndarray, float32, (K, h, w)
            Flat-fielded views.
        progress : callable, optional
            ``progress(done, total, 'RL')`` per iteration.
        should_stop : callable, optional
            True stops with :class:`~napari_ssdpc.errors.Cancelled`.

        Returns
        -------
        Stacks
        """
        iterations = self.settings.iterations
        total = len(HALVES) * iterations
        stacks, history = {}, {}
        for j, (h, rl) in enumerate(self.rl.items()):
            cb = None if progress is None else (lambda i, n, j=j: progress(j * iterations + i, total, "RL"))
            res = rl.run(views[self.halves[h]], iterations, progress=cb, should_stop=should_stop)
            stacks[h], history[h] = res.stack, res.relative_change
            if res.stopped:
                raise Cancelled("reconstruction cancelled")
        dpc, absorption = self.dpc(stacks)
        return Stacks(stacks, dpc, absorption, history, self.h_dpc)

    def dpc(self, stacks) -> tuple[dict, np.ndarray]:
        """DPC stacks (Eq. 1), each slice normalised by the pair's z-summed intensity, and the
        absorption μ per slice from the sum of the four stacks.

        Parameters
        ----------
        stacks : dict
            {half: (Z, h, w)} Richardson-Lucy stacks.

        Returns
        -------
        dpc : dict
            {'ud', 'lr'}: (Z, h, w).
        absorption : ndarray, (Z, h, w)
            μ per slice.
        """
        dpc = {}
        for ax, (a, b) in PAIRS.items():
            background = np.sum(stacks[a] + stacks[b], axis=0)  # the pair's total intensity per pixel
            dpc[ax] = (dpc_image(stacks[a], stacks[b], background=background) * self.mask).astype(np.float32)
        total = sum(stacks[h] for h in HALVES)
        slice_bg = np.median(total[:, self.mask], axis=1)[:, None, None]
        # intensity ≈ I0 (1 − 2μ) at low frequencies (H_abs(0) = 2 I0): μ per slice
        absorption = -0.5 * (total - slice_bg) / np.maximum(np.sum(total, axis=0), 1e-12) * self.mask
        return dpc, absorption.astype(np.float32)
