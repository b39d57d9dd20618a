"""Images of a conventional DPC microscope (an LED array lighting one half of its illumination disk per
image), simulated with the multislice model of :mod:`.multislice`: the ground truth of the DPC
front end's tests (docs/dpc.md).

For each plane wave exp(+i2π w·r) of the illumination disk (Abbe's method; the points of the grid's
frequency lattice every ``step`` lattice units, each weighted by the part of its cell in the disk):
the multislice exit field of the phantom, its propagation to every focal plane z_f (a distance
z_exit − z_f toward the objective), the objective pupil, and the intensity; each pattern adds the
intensities of its half of the disk (a point on the half's edge line counts half). The images
are computed on the camera's grid (or FINE times finer, averaged over each pixel), scaled
to ``photons`` of direct light per pixel and given Poisson noise.
"""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.backend import cpu
from napari_ssdpc.physics.led_transfer import half_plane
from napari_ssdpc.physics.pupil import eta, soft_disk
from napari_ssdpc.physics.waves import defocus_factor
from napari_ssdpc.settings.dpc_optics import DpcOptics
from napari_ssdpc.simulation.multislice import Sampling, Slabs, even_fast
from napari_ssdpc.simulation.phantom_base import Phantom

__all__ = ["simulate_dpc_stack"]

#: Simulation samples per camera pixel and axis (the camera averages them; 1: the camera samples
#: the intensity, band-limited to (NA + NA_ill)/λ, at its pixels).
FINE = 1


def simulate_dpc_stack(
    phantom: Phantom,
    optics: DpcOptics,
    shape,
    *,
    photons: float | None = 20000.0,
    source_spacing_na: float = 0.02,
    seed: int = 0,
) -> np.ndarray:
    """A DPC stack of ``phantom``: one image per pattern, or a z-stack per pattern.

    Parameters
    ----------
    phantom : Phantom
        The sample (centred on the optical axis at x = y = 0), in the optics' medium unless it has its own.
    optics : DpcOptics
    shape : (int, int)
        Camera image (ny, nx), px; the simulation grid is the square that holds it, with a guard band.
    photons : float or None
        Direct light per camera pixel (Poisson noise); None: noise free, direct light 1.
    source_spacing_na : float
        Spacing of the illumination's plane waves, NA units (rounded to the grid's frequency lattice).
    seed : int
        Random seed of the noise.

    Returns
    -------
    ndarray, float32, (P, ny, nx) or (P, F, ny, nx)
        In the order of ``patterns_deg`` (and of ``z_um``).
    """
    ny, nx = (int(n) for n in shape)
    dx = optics.pixel_um / FINE
    z0, z1 = phantom.z_range()
    focal = np.asarray(optics.focal_planes_um, float)
    reach = max(abs(z1 - focal).max(), abs(z0 - focal).max())
    tan = optics.objective_na / math.sqrt(optics.medium_index**2 - optics.objective_na**2)
    guard = reach * tan + 3.0  # room for the defocus blur, µm: the grid is periodic
    n = even_fast(int(math.ceil((max(ny, nx) * optics.pixel_um + 2 * guard) / dx)))
    grid = Sampling(n, dx)
    step = max(1, round(source_spacing_na / (optics.wavelength_um * grid.du)))
    slabs = Slabs(phantom.with_medium(optics.medium_index), optics, grid)  # type: ignore[arg-type]
    u = grid.u()
    ux, uy = np.broadcast_arrays(u[None, :], u[:, None])
    e = eta(ux**2 + uy**2, optics.medium_index, optics.wavelength_um)
    pupil = soft_disk(np.hypot(ux, uy), optics.cutoff, grid.du)
    n_p = len(optics.patterns_deg)
    images = np.zeros((n_p, len(focal), n, n))
    power = np.zeros(n_p)
    r = int(math.ceil(optics.source_radius / grid.du / step)) + 1
    for j in range(-r, r + 1):
        for i in range(-r, r + 1):
            w = np.array([i, j]) * step * grid.du
            cell = soft_disk(np.hypot(*w), optics.source_radius, step * grid.du)
            weights = cell * half_plane(w[0], w[1], optics.patterns_deg, step * grid.du)  # (P,)
            if not weights.any():
                continue
            spec = cpu().fft2(slabs.embed(slabs.exit_envelope(w), n))
            idx = (i * step) % n, (j * step) % n
            p_w = np.roll(pupil, (-idx[1], -idx[0]), axis=(0, 1))  # grid frequency u stands for u + w
            e_w = np.roll(e, (-idx[1], -idx[0]), axis=(0, 1))
            e0 = e[idx[1], idx[0]].real
            for f, zf in enumerate(focal):
                field = cpu().ifft2(spec * p_w * defocus_factor(e_w, slabs.z_exit - zf, e0))
                intensity = np.abs(field) ** 2
                for p in np.flatnonzero(weights):
                    images[p, f] += weights[p] * intensity
            power += weights * pupil[idx[1], idx[0]]
    images /= power[:, None, None, None]
    out = _camera(images, grid, (ny, nx))
    if photons is not None:
        rng = np.random.default_rng(seed)
        out = rng.poisson(out * photons).astype(np.float32)
    return (out if optics.is_stack else out[:, 0]).astype(np.float32)


def _camera(images, grid: Sampling, shape) -> np.ndarray:
    """The camera's pixels: the centred (ny, nx) block of FINE x FINE averages, the optical axis at the
    image centre."""
    ny, nx = shape
    centred = np.fft.fftshift(images, axes=(-2, -1))  # sample n//2 is x = 0
    c = grid.n // 2
    rows = c - (ny * FINE) // 2 + np.arange(ny * FINE)
    cols = c - (nx * FINE) // 2 + np.arange(nx * FINE)
    block = centred[..., rows[:, None], cols[None, :]]
    return block.reshape(*images.shape[:2], ny, FINE, nx, FINE).mean(axis=(3, 5))
