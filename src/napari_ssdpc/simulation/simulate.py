"""Forward simulator of the Fourier light-field microscope: the project's ground truth.

It is deliberately more complete than the reconstruction model (no inverse crime), and keeps
its own discretisation:

1. Köhler illumination sampled as plane waves on the simulation grid's frequency lattice
   (Abbe's method, paper Eq. 2) and multislice propagation through the 3D RI phantom
   (``multislice.py``);
2. the objective pupil, the iris and each lenslet's sub-aperture, the EI intensities resampled
   exactly onto the sensor pixels at M_EI (``imaging.py``), then the camera model
   (``camera.py``);
3. the sample-free white and flat frames computed directly (``sample_free.py``).

``simulate`` runs one frame through all of it. Intensity unit: 1.0 = an EI whose sub-aperture
lies wholly inside the source disk and the objective pupil, with no sample, at the field centre.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.physics.pupil import Pupil, mean_tilt
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation.camera import Camera
from napari_ssdpc.simulation.imaging import Imager, array_as_built, render
from napari_ssdpc.simulation.imperfect import ArrayErrors
from napari_ssdpc.simulation.multislice import DZ_UM, Sampling, Slabs, Source
from napari_ssdpc.simulation.phantom_base import Phantom
from napari_ssdpc.simulation.phantoms import optics_for

__all__ = ["Simulation", "effective_tan_theta", "simulate"]


@dataclass
class Simulation:
    """Result of ``simulate``: raw frame, noise-free intensity and what made them.

    Attributes
    ----------
    frame : ndarray, uint16, (H, W)
        Raw frame, ADU.
    intensity : ndarray, float64, (H, W)
        Noise-free sensor image, intensity unit.
    grid : Grid
        The array on the sensor.
    lenslets : list of Lenslet
        The lenslets as built.
    phantom : Phantom or None
        The sample, bound to its medium (None: no sample).
    optics : Optics
        The optics used (with the phantom's medium, if it has one).
    source : Source
    sampling : Sampling
    camera : Camera
    seconds : float
        Wall time of the simulation, s.
    n_source_points : int
        Plane waves summed.
    info : dict
        ``subgrid`` (multislice sub-grid side, samples; 0 without sample), ``screens`` (non-empty
        slabs), ``grid_n`` (object grid side, samples), ``crop`` (lenslet crop width, lattice units).
    """

    frame: np.ndarray
    intensity: np.ndarray
    grid: Grid
    lenslets: list
    phantom: Phantom | None
    optics: Optics
    source: Source
    sampling: Sampling
    camera: Camera
    seconds: float = 0.0
    n_source_points: int = 0
    info: dict = field(default_factory=dict)


def simulate(
    phantom: Phantom | None,
    optics: Optics,
    grid: Grid | None = None,
    camera: Camera | None = None,
    source: Source | None = None,
    rng=None,
    progress=None,
    *,
    dz_um: float = DZ_UM,
    array: ArrayErrors | None = None,
) -> Simulation:
    """Simulate one raw frame of ``phantom`` (None: no sample, the flat frame).

    ``progress(done, total)`` is called after every source point. A phantom with its
    own ``medium_index`` (e.g. ``cell()``, water) replaces the optics' medium; the
    optics used is returned as ``Simulation.optics``.

    Parameters
    ----------
    phantom : Phantom or None
        The sample; None: no sample (a flat frame).
    optics : Optics
    grid : Grid, optional
        Default the nominal grid.
    camera : Camera, optional
        Default ``Camera()``.
    source : Source, optional
        Sampling of the condenser disk; default ``Source()``.
    rng : numpy.random.Generator or int, optional
        Generator or seed of the noise; None: ``camera.seed``.
    progress : callable, optional
        ``progress(done, total)`` per source point.
    dz_um : float
        Largest slab thickness of the multislice, µm.
    array : ArrayErrors, optional
        A misaligned, imperfect lenslet array.

    Returns
    -------
    Simulation
    """
    t0 = time.perf_counter()
    optics = optics_for(phantom, optics)
    if phantom is not None:
        phantom = phantom.with_medium(optics.medium_index)
    grid, camera, lenslets, centres = array_as_built(optics, grid, camera, array)
    source = source or Source()
    sampling = Sampling.for_optics(optics)
    imager = Imager(optics, sampling, lenslets)
    idx, w, wgt = source.points(optics, sampling)
    slabs = Slabs(phantom, optics, sampling, dz_um) if phantom is not None else None

    def spectrum(j):
        if slabs is None:
            return imager.empty_spectrum(idx[j])
        v = slabs.embed(slabs.exit_envelope(w[j]), sampling.n)
        return imager.image_spectrum(v, idx[j], slabs.z_exit)

    coeffs = imager.sum_sources(idx, wgt, spectrum, progress)
    intensity = render(coeffs, centres, optics, sampling, grid, camera)
    frame = camera.apply(intensity, camera.rng(rng))
    info = {
        "subgrid": slabs.ns if slabs else 0,
        "screens": len(slabs.screens) if slabs else 0,
        "grid_n": sampling.n,
        "crop": imager.nc,
    }
    return Simulation(
        frame,
        intensity,
        grid,
        lenslets,
        phantom,
        optics,
        source,
        sampling,
        camera,
        time.perf_counter() - t0,
        len(idx),
        info,
    )


# ------------------------------------------------------------------------------ helpers
def effective_tan_theta(optics: Optics, lenslet, supersample: int = 400) -> np.ndarray:
    """|pupil|²-weighted mean over A_k of tanθ(u)·û(u) (vector, object frame).

    A point at depth z appears displaced by z times this vector in the EI of
    ``lenslet`` (docs/conventions.md); it is about 6 % below the centre value for clipped EIs.

    Parameters
    ----------
    optics : Optics
    lenslet : Lenslet
    supersample : int
        Samples across the sub-aperture.

    Returns
    -------
    ndarray, (2,)
        tanθ·û (x, y), dimensionless: µm of lateral shift per µm of depth.
    """
    pupil = Pupil.of(optics)
    u_k, rho, _ = pupil.lenslet(lenslet)  # its own sub-aperture
    t = np.linspace(-rho, rho, supersample)
    ux, uy = np.meshgrid(u_k[0] + t, u_k[1] + t)
    a = pupil.subaperture(ux, uy, u_k, rho=rho)
    return mean_tilt(optics, a[a].astype(float), ux[a], uy[a])  # tanθ·û = u/η(u), averaged over A_k
