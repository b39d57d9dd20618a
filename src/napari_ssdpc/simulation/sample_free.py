"""Sample-free frames of the simulator: the white frame (condenser fully open) and the flat
frame (the sample's condenser, no sample), computed directly from the lenslet windows."""

from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft
from scipy import special

from napari_ssdpc.backend import cpu
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.physics.pupil import Pupil
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.camera import Camera
from napari_ssdpc.simulation.imaging import Imager, array_as_built, crop_size, render
from napari_ssdpc.simulation.imperfect import ArrayErrors
from napari_ssdpc.simulation.multislice import Sampling, Source


def white_intensity(
    optics: Optics, grid: Grid | None = None, camera: Camera | None = None, *, array: ArrayErrors | None = None
) -> np.ndarray:
    """Noise-free white frame (condenser fully open, σ = 1), intensity unit.

    Each EI is the iris disk, imaged through the lenslet's sub-aperture A_k in the
    incoherent limit (σ = 1), with brightness = the exact fraction of the sub-aperture
    inside the objective pupil (circle-overlap formula; no source quantisation). The
    brightness is set at the EI centre (the optical axis in the object): the lenslet
    PSF's tails spread ~1 % of the light past the field stop, which would otherwise
    lower the plateau by that much (see docs/simulator.md).

    Parameters
    ----------
    optics : Optics
    grid : Grid, optional
        Default the nominal grid.
    camera : Camera, optional
        Its illumination fall-off is applied; default ``Camera()``.
    array : ArrayErrors, optional
        Errors of the array; None: the ideal lattice.

    Returns
    -------
    ndarray, float64, (H, W)
        Intensity unit.
    """
    grid, camera, lenslets, centres = array_as_built(optics, grid, camera, array)
    sampling = Sampling.for_optics(optics)
    nc = crop_size(optics, sampling)
    f = np.fft.fftfreq(nc, sampling.size_um / nc)
    fr = np.hypot(f[None, :], f[:, None])
    R, L = optics.field_radius_um, sampling.size_um
    with np.errstate(invalid="ignore", divide="ignore"):
        disk = np.where(fr > 0, R * special.j1(2 * np.pi * R * fr) / fr, np.pi * R * R) / L**2
    coeffs = []
    pupil = Pupil.of(optics)
    for ln in lenslets:
        if ln.fraction <= 0:  # moved out of the pupil (imperfect.ArrayErrors): dark
            coeffs.append(np.zeros_like(disk))
            continue
        c = disk * _incoherent_otf(ln, optics, sampling.du, nc)
        # value at the EI centre = the exact fraction (the lenslet's own sub-aperture where it differs)
        fraction = pupil.area_fraction(ln) if pupil.lenslet_terms else ln.fraction
        coeffs.append(c * (fraction / c.sum().real))
    coeffs = np.array(coeffs)
    return render(coeffs.astype(np.complex128), centres, optics, sampling, grid, camera)


def _incoherent_otf(lenslet, optics, du, nc, q=4):
    """Normalised autocorrelation of the lenslet's pupil behind the field stop (its own sub-aperture
    and defocus: without a sample the objective's phase is a constant phase per plane wave before
    the stop, and leaves the stop's image alone) at lags that are multiples of du."""
    pupil = Pupil.of(optics)
    u_k, rho, _ = pupil.lenslet(lenslet)
    d = du / q
    m = int(math.ceil((rho + 2 * du) / d))
    t = np.arange(-m, m + 1) * d
    sx, sy = u_k[0] + t[None, :], u_k[1] + t[:, None]
    a = pupil.field(sx, sy, lenslet, objective=False) * 1.0  # bool -> float for the nominal optics
    N = sfft.next_fast_len(2 * len(t) + 1)
    ac = cpu().ifft2(np.abs(cpu().fft2(a, s=(N, N))) ** 2)  # complex for an aberrated pupil
    lag = (np.fft.fftfreq(nc, 1.0 / nc).astype(int) * q) % N
    otf = ac[np.ix_(lag, lag)]
    return otf / ac[0, 0]


def white_frame(
    optics: Optics,
    grid: Grid | None = None,
    camera: Camera | None = None,
    rng=None,
    *,
    array: ArrayErrors | None = None,
) -> np.ndarray:
    """Raw uint16 white frame (σ = 1): every lenslet inside the pupil is lit, edge
    lenslets at the exact fraction of their sub-aperture inside the pupil.

    Parameters
    ----------
    optics : Optics
    grid : Grid, optional
        Default the nominal grid.
    camera : Camera, optional
        Default ``Camera()``.
    rng : numpy.random.Generator or int, optional
        Generator or seed of the noise; None: ``camera.seed``.
    array : ArrayErrors, optional
        Errors of the array; None: the ideal lattice.

    Returns
    -------
    ndarray, uint16, (H, W)
        ADU.
    """
    camera = camera or Camera()
    return camera.apply(white_intensity(optics, grid, camera, array=array), camera.rng(rng))


def flat_intensity(
    optics: Optics,
    grid: Grid | None = None,
    camera: Camera | None = None,
    source: Source | None = None,
    progress=None,
    *,
    array: ArrayErrors | None = None,
) -> np.ndarray:
    """Noise-free flat frame at the optics' condenser NA, intensity unit.

    Same source sampling and the same imaging code as ``simulate``, so that
    ``simulate(...).intensity / flat_intensity(...)`` is exactly 1 where the sample
    does not scatter.

    Parameters
    ----------
    optics : Optics
    grid : Grid, optional
        Default the nominal grid.
    camera : Camera, optional
        Its illumination fall-off is applied; default ``Camera()``.
    source : Source, optional
        Sampling of the condenser disk; default ``Source()``.
    progress : callable, optional
        ``progress(done, total)`` per source point.
    array : ArrayErrors, optional
        Errors of the array; None: the ideal lattice.

    Returns
    -------
    ndarray, float64, (H, W)
        Intensity unit.
    """
    grid, camera, lenslets, centres = array_as_built(optics, grid, camera, array)
    sampling = Sampling.for_optics(optics)
    imager = Imager(optics, sampling, lenslets)
    idx, _, wgt = (source or Source()).points(optics, sampling)
    coeffs = imager.sum_sources(idx, wgt, lambda j: imager.empty_spectrum(idx[j]), progress)
    return render(coeffs, centres, optics, sampling, grid, camera)


def flat_frame(
    optics: Optics,
    grid: Grid | None = None,
    camera: Camera | None = None,
    rng=None,
    source: Source | None = None,
    *,
    array: ArrayErrors | None = None,
    progress=None,
) -> np.ndarray:
    """Raw uint16 flat frame (no sample) at the sample's condenser NA (σ < 1).

    Parameters
    ----------
    optics : Optics
    grid : Grid, optional
        Default the nominal grid.
    camera : Camera, optional
        Default ``Camera()``.
    rng : numpy.random.Generator or int, optional
        Generator or seed of the noise; None: ``camera.seed``.
    source : Source, optional
        Sampling of the condenser disk; default ``Source()``.
    array : ArrayErrors, optional
        Errors of the array; None: the ideal lattice.
    progress : callable, optional
        ``progress(done, total)`` per source point.

    Returns
    -------
    ndarray, uint16, (H, W)
        ADU.
    """
    camera = camera or Camera()
    intensity = flat_intensity(optics, grid, camera, source, array=array, progress=progress)
    return camera.apply(intensity, camera.rng(rng))
