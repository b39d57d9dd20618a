"""Camera and illumination model of the simulator.

Intensity unit (used by every simulator function): 1.0 is the brightness of an
elemental image (EI) whose pupil sub-aperture lies wholly inside the source disk and
inside the objective pupil, with no sample, at the centre of the field of view.

``Camera.apply`` turns such an intensity image into a raw uint16 frame:
photo-electrons ``e = intensity * exposure_e`` -> Poisson shot noise -> full-well
clip -> Gaussian read noise -> ``ADU = gain * e + dark_offset`` -> rounding -> clip
at ``2**bit_depth - 1`` (ADC saturation).

``falloff`` describes the illumination, not the sensor: the Köhler illumination in
the object plane drops smoothly as ``1 - falloff * (r / r_field)**2`` (r measured
from the optical axis in the object plane, r_field = the field-stop radius). It is
the same in every EI, so a flat frame taken at the same condenser setting captures
it. The simulator applies it while it renders the EIs (see ``illumination``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from napari_ssdpc.errors import SsdpcError


@dataclass(frozen=True)
class Camera:
    """Sensor model. ``noise=False`` gives the noise-free (but quantised and clipped) frame.

    Attributes
    ----------
    gain_adu_per_e : float
        Conversion gain, ADU per photo-electron.
    dark_offset_adu : float
        Dark (bias) offset added to every pixel, ADU.
    read_noise_e : float
        Gaussian read noise, electrons rms.
    full_well_e : float
        Full-well capacity, electrons (clipped above).
    bit_depth : int
        ADC bits, 1-16; values saturate at ``2**bit_depth - 1`` ADU.
    exposure_e : float
        Photo-electrons per pixel at intensity 1.0 (a fully lit EI without sample).
    falloff : float
        Relative drop of the Köhler illumination at the field-stop radius, in [0, 1).
    seed : int or None
        Seed of the default random generator (None: fresh entropy).
    noise : bool
        Add shot and read noise.
    """

    gain_adu_per_e: float = 0.25
    dark_offset_adu: float = 100.0
    read_noise_e: float = 2.5
    full_well_e: float = 20000.0
    bit_depth: int = 12
    exposure_e: float = 12000.0
    falloff: float = 0.15
    seed: int | None = None
    noise: bool = True

    def __post_init__(self):
        for name in ("gain_adu_per_e", "full_well_e", "exposure_e"):
            if not getattr(self, name) > 0:
                raise SsdpcError(f"Camera.{name} must be > 0, got {getattr(self, name)}")
        if self.read_noise_e < 0 or self.dark_offset_adu < 0:
            raise SsdpcError("Camera.read_noise_e and Camera.dark_offset_adu must be >= 0")
        if not 1 <= int(self.bit_depth) <= 16:
            raise SsdpcError(f"Camera.bit_depth must be 1-16 for a uint16 frame, got {self.bit_depth}")
        if not 0 <= self.falloff < 1:
            raise SsdpcError(f"Camera.falloff must be in [0, 1), got {self.falloff}")

    @property
    def max_adu(self) -> int:
        """Largest value of the ADC, ADU."""
        return 2 ** int(self.bit_depth) - 1

    def rng(self, rng=None) -> np.random.Generator:
        """The generator to use: ``rng`` if given, else one seeded with ``seed``.

        Parameters
        ----------
        rng : numpy.random.Generator or int, optional
            A generator (returned as it is) or a seed; None: ``seed``.

        Returns
        -------
        numpy.random.Generator
        """
        if isinstance(rng, np.random.Generator):
            return rng
        return np.random.default_rng(self.seed if rng is None else rng)

    def adu(self, intensity) -> np.ndarray:
        """Expected (noise-free, unquantised) ADU image, with full-well and ADC clipping.

        Parameters
        ----------
        intensity : ndarray
            Intensity unit (1 = a fully lit EI without sample).

        Returns
        -------
        ndarray, float64
            ADU, shaped like ``intensity``.
        """
        e = np.clip(np.asarray(intensity, dtype=np.float64), 0, None) * self.exposure_e
        e = np.minimum(e, self.full_well_e)
        return np.clip(e * self.gain_adu_per_e + self.dark_offset_adu, 0, self.max_adu)

    def apply(self, intensity, rng=None) -> np.ndarray:
        """Raw uint16 frame of an intensity image (unit: see module docstring).

        Parameters
        ----------
        intensity : ndarray, (H, W)
            Intensity unit (1 = a fully lit EI without sample).
        rng : numpy.random.Generator or int, optional
            Generator or seed of the noise; None: ``seed``.

        Returns
        -------
        ndarray, uint16, (H, W)
            ADU.
        """
        intensity = np.asarray(intensity, dtype=np.float64)
        if not np.all(np.isfinite(intensity)):
            raise SsdpcError("intensity contains NaN or inf; check the simulation input")
        if not self.noise:
            return np.rint(self.adu(intensity)).astype(np.uint16)
        g = self.rng(rng)
        e = g.poisson(np.clip(intensity, 0, None) * self.exposure_e).astype(np.float64)
        e = np.minimum(e, self.full_well_e)
        e += g.normal(0.0, self.read_noise_e, size=e.shape)
        adu = e * self.gain_adu_per_e + self.dark_offset_adu
        return np.clip(np.rint(adu), 0, self.max_adu).astype(np.uint16)

    def illumination(self, r_um, field_radius_um) -> np.ndarray:
        """Relative Köhler illumination at object-plane radius ``r_um`` (1 on the axis).

        Parameters
        ----------
        r_um : ndarray
            Radius in the object plane, µm.
        field_radius_um : float
            Field-stop radius, µm.

        Returns
        -------
        ndarray, float64
            Relative illumination in [0, 1], shaped like ``r_um``.
        """
        r = np.asarray(r_um, dtype=np.float64) / float(field_radius_um)
        return np.clip(1.0 - self.falloff * r * r, 0.0, None)
