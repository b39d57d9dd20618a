"""Objects in a Δn volume: segmentation relative to the noise, and per-object measurements.

The rule (docs/measurements.md):

1. **Noise.** σ = 1.4826 · MAD(Δn) over the whole volume: a robust standard deviation of the
   background, unbiased while the objects fill less than about half of the voxels.
2. **Objects.** Hysteresis thresholding of the signed Δn (``sign`` · Δn): a voxel above the low
   threshold belongs to an object when it connects (26-connectivity) to a voxel above the seed
   threshold; connected components smaller than ``min_volume_um3`` are dropped (specks of noise).
   The thresholds are ``k_low`` σ and ``k`` σ, but never below ``fraction_low`` and ``fraction`` of
   the frame's peak signed Δn: a `tv` reconstruction sets most of the background exactly to zero
   (σ ≈ 0) and leaves a faint haze around its objects, which the noise alone cannot tell apart.
3. **Each object's region** is its component grown by the resolution, an ellipsoidal margin of one
   FWHM along each axis (no voxel given to two objects): the blurred tails of an object hold much
   of its Δn.
4. **Measurements** over that region: the integrated Δn ∫Δn dV (µm³), the dry mass ∫Δn dV / α (pg,
   α the specific refraction increment, µm³/pg), the Δn-weighted centroid (µm) and the volume of the
   uniform ellipsoid with the same second moments once the resolution's are removed (convolution adds
   covariances: Σ_object = Σ_measured − Σ_PSF; a uniform ellipsoid of semi-axes a has Σ = a²/5, so
   V = 4π/3 · √det(5 Σ_object)). The mean RI is n_medium + ∫Δn dV / V; the peak RI is the extreme Δn
   of the component (lowered by the blur, as the reconstruction shows it).

An object smaller than :data:`RESOLVED_FRACTION` of the resolution along any axis has no measurable
volume: its volume and mean RI are NaN; its dry mass and centroid are still measured.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import ndimage

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.reconstruction import ReconstructionSettings
from napari_ssdpc.statistics import robust_sigma

__all__ = [
    "DEFAULT_RULE",
    "DEFAULT_RESOLUTION_UM",
    "FWHM_PER_SIGMA",
    "REFRACTION_INCREMENT_UM3_PG",
    "RESOLVED_FRACTION",
    "ObjectRule",
    "measure_objects",
    "noise_sigma",
    "segment",
]

#: The default specific refraction increment α, µm³/pg (the reconstruction settings' own default).
REFRACTION_INCREMENT_UM3_PG: float = float(
    ReconstructionSettings.model_fields["refraction_increment_um3_pg"].default  # type: ignore[arg-type]
)
#: FWHM of a Gaussian over its standard deviation, 2√(2 ln 2).
FWHM_PER_SIGMA = float(2 * np.sqrt(2 * np.log(2)))
#: An object is resolved along an axis when its diameter is at least this fraction of the FWHM there:
#: below it the blur's variance is over 7 times the object's own (a uniform ellipsoid: (0.35 FWHM)²/5
#: against (FWHM/2.355)²), and removing it multiplies the relative error of the measured one by over 8.
RESOLVED_FRACTION = 0.7
#: (FWHM_z, FWHM_xy) µm: the Gaussian blur that best matches `tv`'s reconstruction of a weak 6 µm bead
#: at condenser NA 0.3 (least squares; `tv` keeps lateral edges sharp), docs/measurements.md.
DEFAULT_RESOLUTION_UM = (9.0, 1.0)


@dataclass(frozen=True)
class ObjectRule:
    """How objects are found and measured (docs/measurements.md).

    Attributes
    ----------
    k : float
        Seed threshold, in noise σ (5: about one noise voxel in 3.5 million passes).
    k_low : float
        Hysteresis threshold, in noise σ: the extent of an object around its seeds.
    fraction : float
        The seed threshold is at least this fraction of the frame's peak signed Δn.
    fraction_low : float
        The low threshold is at least this fraction of the frame's peak signed Δn.
    min_volume_um3 : float
        Components smaller than this (their voxels' volume, µm³) are dropped.
    resolution_um : (float, float)
        (FWHM_z, FWHM_xy) of the reconstruction's point spread, µm: the margin of each object's
        region and the blur removed from its second moments.
    sign : {'denser', 'lighter'}
        Objects above the medium's index (cells in water) or below it (a PMMA bead in oil).
    noise : float or None
        The background σ of Δn; None: 1.4826 · MAD of the volume.
    """

    k: float = 5.0
    k_low: float = 2.5
    fraction: float = 0.2
    fraction_low: float = 0.05
    min_volume_um3: float = 20.0
    resolution_um: tuple[float, float] = DEFAULT_RESOLUTION_UM
    sign: Literal["denser", "lighter"] = "denser"
    noise: float | None = None

    def __post_init__(self):
        if not (np.isfinite(self.k) and np.isfinite(self.k_low) and 0 < self.k_low <= self.k):
            raise SsdpcError(f"thresholds k {self.k}, k_low {self.k_low}: give 0 < k_low <= k (in noise σ)")
        if not (0 <= self.fraction_low <= self.fraction < 1):
            raise SsdpcError(
                f"fractions {self.fraction}, {self.fraction_low} of the peak: give 0 <= fraction_low <= fraction < 1"
            )
        if not self.min_volume_um3 >= 0:
            raise SsdpcError(f"min_volume_um3 {self.min_volume_um3}: give a volume >= 0 µm³")
        if len(self.resolution_um) != 2 or not all(np.isfinite(r) and r >= 0 for r in self.resolution_um):
            raise SsdpcError(f"resolution_um {self.resolution_um}: give (FWHM_z, FWHM_xy) >= 0 µm")
        if self.sign not in ("denser", "lighter"):
            raise SsdpcError(f"sign {self.sign!r}: give 'denser' or 'lighter'")
        if self.noise is not None and not (np.isfinite(self.noise) and self.noise > 0):
            raise SsdpcError(f"noise {self.noise}: give a background σ of Δn > 0, or None to estimate it")

    @property
    def polarity(self) -> int:
        """+1 for denser objects, -1 for lighter ones."""
        return 1 if self.sign == "denser" else -1


#: The rule with its documented defaults.
DEFAULT_RULE = ObjectRule()


def noise_sigma(delta_n) -> float:
    """Robust standard deviation of the background Δn: 1.4826 · median |Δn − median(Δn)|.

    Parameters
    ----------
    delta_n : ndarray
        Δn, any shape; NaN voxels are ignored.

    Returns
    -------
    float
        σ of Δn (unitless); 0 for a volume without noise.
    """
    d = np.asarray(delta_n, dtype=np.float64)
    d = d[np.isfinite(d)]
    if d.size == 0:
        raise SsdpcError("the Δn volume holds no finite value; was the frame reconstructed?")
    return robust_sigma(d)


def _voxel(z_um, y_um, x_um) -> tuple[float, float, float]:
    spacing = []
    for name, c in (("z", z_um), ("y", y_um), ("x", x_um)):
        c = np.asarray(c, dtype=np.float64)
        step = float(c[1] - c[0]) if len(c) > 1 else 1.0
        if not step > 0:
            raise SsdpcError(f"the {name} coordinates must increase; got a step of {step} µm")
        spacing.append(step)
    return spacing[0], spacing[1], spacing[2]


def segment(delta_n, voxel_um, rule: ObjectRule = DEFAULT_RULE) -> tuple[np.ndarray, float, float]:
    """Label the objects of a Δn volume (steps 1-2 of the module's rule).

    Parameters
    ----------
    delta_n : ndarray, (z, y, x)
        Δn, unitless.
    voxel_um : (float, float, float)
        (dz, dy, dx), µm.
    rule : ObjectRule

    Returns
    -------
    labels : ndarray of int32, (z, y, x)
        0 for the background, 1..N the objects, largest first.
    sigma : float
        The background σ of Δn.
    low : float
        The low threshold of the signed Δn (an object's extent).
    """
    d = np.asarray(delta_n, dtype=np.float32)
    if d.ndim != 3:
        raise SsdpcError(f"objects are segmented in a (z, y, x) volume, got shape {d.shape}")
    sigma = rule.noise if rule.noise is not None else noise_sigma(d)
    signed = np.nan_to_num(rule.polarity * d, nan=0.0)
    peak = max(float(signed.max()), 0.0)
    low, high = max(rule.k_low * sigma, rule.fraction_low * peak), max(rule.k * sigma, rule.fraction * peak)
    if not high > 0:
        raise SsdpcError(
            "the Δn volume has no background noise and no object to set a threshold by; give the noise σ (noise=...)"
        )
    from skimage.filters import apply_hysteresis_threshold

    mask = apply_hysteresis_threshold(signed, low, high)
    labels, n = ndimage.label(mask, structure=np.ones((3, 3, 3), bool))
    sizes = np.bincount(labels.ravel(), minlength=n + 1)[1:] * float(np.prod(voxel_um))
    keep = np.flatnonzero(sizes >= rule.min_volume_um3)
    order = keep[np.argsort(-sizes[keep], kind="stable")]
    relabel = np.zeros(n + 1, np.int32)
    relabel[order + 1] = np.arange(1, len(order) + 1, dtype=np.int32)
    return relabel[labels], float(sigma), float(low)


def _regions(labels, voxel_um, resolution_um) -> np.ndarray:
    """Each object's component grown by an ellipsoidal margin of (FWHM_z, FWHM_xy, FWHM_xy): every
    voxel within it goes to the nearest object (in margin units)."""
    rz, rxy = resolution_um
    if rz <= 0 and rxy <= 0 or not labels.any():
        return labels
    dz, dy, dx = voxel_um
    big = 1e6  # an axis without margin: a voxel off the component along it is never reached
    sampling = (dz / rz if rz > 0 else big, dy / rxy if rxy > 0 else big, dx / rxy if rxy > 0 else big)
    dist, nearest = ndimage.distance_transform_edt(labels == 0, sampling=sampling, return_indices=True)
    grown = labels[tuple(nearest)]
    grown[dist > 1.0] = 0
    return grown


def _resolved(cov, psf_var) -> bool:
    """Whether the object's own extent (the equivalent ellipsoid's diameter 2√(5 Σ_ii)) reaches
    :data:`RESOLVED_FRACTION` of the resolution's FWHM along each axis, with Σ positive definite."""
    if not np.all(np.linalg.eigvalsh(cov) > 0):
        return False
    diameter = 2 * np.sqrt(5 * np.diag(cov))
    return bool(np.all(diameter >= RESOLVED_FRACTION * FWHM_PER_SIGMA * np.sqrt(psf_var)))


def measure_objects(
    delta_n,
    z_um,
    y_um,
    x_um,
    *,
    n_medium: float,
    rule: ObjectRule = DEFAULT_RULE,
    refraction_increment_um3_pg: float = REFRACTION_INCREMENT_UM3_PG,
) -> list[dict]:
    """Find the objects of one Δn volume and measure each (the module's rule).

    Parameters
    ----------
    delta_n : ndarray, (z, y, x)
        Δn = RI − n_medium, unitless.
    z_um, y_um, x_um : ndarray, 1D
        Plane and pixel centres, µm, evenly spaced.
    n_medium : float
        Refractive index of the medium.
    rule : ObjectRule
        Thresholds, minimum volume, resolution and sign.
    refraction_increment_um3_pg : float
        Specific refraction increment α, µm³/pg.

    Returns
    -------
    list of dict
        One per object, largest first: ``object`` (its label), ``x_um``, ``y_um``, ``z_um`` (Δn-weighted
        centroid, µm), ``volume_um3`` (equivalent ellipsoid, NaN when unresolved), ``mean_ri``,
        ``peak_ri``, ``integrated_dn_um3`` (∫Δn dV, µm³), ``dry_mass_pg``, ``voxels`` (of the
        component), ``at_edge`` (1: the region reaches the volume's edge, where the object's tails are
        cut off and its volume and mass read low), ``noise_dn`` (the background σ), ``threshold_dn``
        (the low threshold, signed Δn).
    """
    if not refraction_increment_um3_pg > 0:
        raise SsdpcError(f"refraction increment {refraction_increment_um3_pg}: give α > 0 µm³/pg")
    d = np.nan_to_num(np.asarray(delta_n, dtype=np.float64), nan=0.0)
    coords = [np.asarray(c, dtype=np.float64) for c in (z_um, y_um, x_um)]
    if d.shape != tuple(len(c) for c in coords):
        raise SsdpcError(f"Δn of shape {d.shape} does not match its coordinates {tuple(len(c) for c in coords)}")
    voxel = _voxel(*coords)
    dv = float(np.prod(voxel))
    labels, sigma, low = segment(d, voxel, rule)
    regions = _regions(labels, voxel, rule.resolution_um)
    psf_var = np.array([rule.resolution_um[0], rule.resolution_um[1], rule.resolution_um[1]]) ** 2 / FWHM_PER_SIGMA**2
    out = []
    for i, sl in enumerate(ndimage.find_objects(regions), start=1):
        if sl is None:
            continue
        inside = regions[sl] == i
        w = d[sl][inside]
        pos = np.stack([g[inside] for g in np.meshgrid(*(c[s] for c, s in zip(coords, sl)), indexing="ij")])
        mass = float(w.sum())  # Σ Δn over the region: ∫Δn dV / dV
        centroid = pos @ w / mass
        offset = pos - centroid[:, None]
        cov = (offset * w) @ offset.T / mass - np.diag(psf_var)
        volume = float("nan")
        if _resolved(cov, psf_var):
            volume = 4.0 / 3.0 * np.pi * float(np.sqrt(np.linalg.det(5.0 * cov)))
        integrated = mass * dv
        core = d[sl][labels[sl] == i]
        peak = float(core.max() if rule.polarity > 0 else core.min())
        out.append(
            {
                "object": i,
                "x_um": float(centroid[2]),
                "y_um": float(centroid[1]),
                "z_um": float(centroid[0]),
                "volume_um3": float(volume),
                "mean_ri": float(n_medium + integrated / volume),
                "peak_ri": float(n_medium + peak),
                "integrated_dn_um3": float(integrated),
                "dry_mass_pg": float(integrated / refraction_increment_um3_pg),
                "voxels": int(core.size),
                "at_edge": int(any(s.start == 0 or s.stop == n for s, n in zip(sl, d.shape))),
                "noise_dn": sigma,
                "threshold_dn": rule.polarity * low,
            }
        )
    return out
