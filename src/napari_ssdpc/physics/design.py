"""The design calculator: paper Eqs. 8-14, the depth of field, and what the condenser NA leaves.

The paper's Eq. 13 as printed (tanθ' = √2 d/f_ml) gives R_z = 4.2 µm for its optics; its printed
20.6 µm (and the measured 21.96 µm) come out with tanθ' = √2 d/f_fl. Both are reported.

Only lenslets whose sub-aperture straddles the edge of the source disk carry first-order phase
contrast (docs/conventions.md), so the axial resolution a reconstruction reaches depends on the
condenser NA: ``expected_axial_fwhm_um`` scales R_z by the parallax of the outermost straddling
lenslet against that of the outermost lenslet in the pupil. It matches the measured FWHM of a
13 µm bead to about 10% at condenser NA 0.3 (22 µm) and is an upper estimate at 0.1 (52-75 µm).
"""

from __future__ import annotations

import math

import numpy as np

from napari_ssdpc.physics.geometry import nominal_lenslets, tan_theta
from napari_ssdpc.physics.lattice import lenslet_case
from napari_ssdpc.settings.lenslets import Lenslet
from napari_ssdpc.settings.optics import Optics

__all__ = ["MIN_STRADDLING", "design", "design_table", "design_warnings"]

#: Fewer lenslets than this straddling the source edge give a poor axial resolution.
MIN_STRADDLING = 8


def design(optics: Optics) -> dict:
    """The design numbers of paper Eqs. 8-14 and the DOF limits of its section 3.2.

    Parameters
    ----------
    optics : Optics
        The instrument.

    Returns
    -------
    dict
        Lengths in µm (keys end in ``_um``), magnifications, lenslet counts by regime
        (``lenslets_inside``, ``lenslets_straddling``, ``lenslets_outside`` the source disk) and
        ``expected_axial_fwhm_um``, the axial resolution the straddling lenslets give.
    """
    lam, M, NA = optics.wavelength_um, optics.magnification, optics.na
    f_fl, f_ml = optics.fourier_lens_mm * 1e3, optics.mla_focal_length_mm * 1e3
    f_tube, f_obj, d = optics.tube_lens_mm * 1e3, optics.f_obj_um, optics.pitch_um
    na_ml = optics.lenslet_radius_um / f_ml
    r_nip = lam / (2 * na_ml)  # Eq. 11
    r_xy = r_nip * (f_fl / f_ml) / M  # Eq. 12
    tan_printed = math.sqrt(2) * d / f_ml  # Eq. 13 as printed
    tan_ffl = math.sqrt(2) * d / f_fl  # reproduces the printed 20.6 µm
    rz_printed = r_nip * (f_fl / f_ml) / tan_printed / M**2
    rz_ffl = r_nip * (f_fl / f_ml) / tan_ffl / M**2
    m_t = (2 * f_fl * NA / f_tube) * (f_obj / d)
    dof_fwhm = m_t**2 * lam / NA**2 + optics.pixel_um * m_t**2 / (M * NA)  # Eq. 14
    dof_pitch = d * (f_fl / f_ml) / (d / f_fl) / M**2
    lens = nominal_lenslets(optics)
    usable = [ln for ln in lens if ln.fraction >= 0.5]
    tan_edge = float(np.max(tan_theta(optics, np.array([ln.u for ln in lens]))))
    regimes = [lenslet_case(optics, ln) for ln in lens]
    return {
        "ei_radius_um": optics.ei_radius_um,  # Eq. 8
        "iris_radius_um": optics.iris_radius_nip_um,  # Eq. 9
        "fov_um": optics.fov_um,  # Eq. 10
        "r_nip_um": r_nip,  # Eq. 11
        "r_xy_um": r_xy,  # Eq. 12
        "r_z_printed_um": rz_printed,
        "r_z_ffl_um": rz_ffl,
        "m_t": m_t,
        "dof_fwhm_um": dof_fwhm,
        "dof_full_um": 2 * dof_fwhm,
        "dof_pitch_um": dof_pitch,
        "dof_um": min(2 * dof_fwhm, dof_pitch),
        "medium_index": optics.medium_index,
        "m_ei": optics.m_ei,
        "object_pixel_um": optics.object_pixel_um,
        "f_obj_um": f_obj,
        "m_r": optics.m_r,
        "subaperture_na": optics.subaperture_na,
        "sigma": optics.sigma,
        "pitch_px": optics.pitch_px,
        "ei_radius_px": optics.ei_radius_px,
        "lenslets_in_pupil": len(lens),
        "lenslets_usable": len(usable),
        "nyquist_voxel_xy_um": r_xy / 2,
        "nyquist_voxel_z_um": rz_ffl / 2,
        "max_tan_theta": tan_edge,
        "lenslets_inside": regimes.count("inside"),
        "lenslets_straddling": regimes.count("straddling"),
        "lenslets_outside": regimes.count("outside"),
        "expected_axial_fwhm_um": _expected_axial_fwhm(optics, lens, regimes, rz_ffl),
    }


def _expected_axial_fwhm(optics: Optics, lens: list[Lenslet], regimes: list[str], rz_um: float) -> float:
    tan = tan_theta(optics, np.array([ln.u for ln in lens]))
    straddling = [t for t, r in zip(tan, regimes) if r == "straddling"]
    if not straddling:
        return math.inf
    return float(rz_um * np.max(tan) / max(straddling))


def design_warnings(optics: Optics) -> list[str]:
    """What the condenser NA costs, one sentence each (empty when nothing is wrong).

    Parameters
    ----------
    optics : Optics

    Returns
    -------
    list of str
    """
    d = design(optics)
    n = d["lenslets_straddling"]
    if n >= MIN_STRADDLING:
        return []
    fwhm = d["expected_axial_fwhm_um"]
    reach = "no axial resolution" if not math.isfinite(fwhm) else f"an axial FWHM near {fwhm:.0f} µm"
    return [
        f"only {n} lenslets straddle the source edge at condenser_na {optics.condenser_na:g}: expect {reach} "
        f"instead of {d['r_z_ffl_um']:.1f} µm; a condenser NA near {0.75 * optics.na:.2f} (sigma 0.75) is better"
    ]


def design_table(optics: Optics, short: bool = False) -> str:
    """Readable design summary for ``ssdpc design`` and the napari Optics step.

    Parameters
    ----------
    optics : Optics
    short : bool
        A few short lines (the napari Optics step) instead of the full table (``ssdpc design``).

    Returns
    -------
    str
        One row per quantity with its value and unit, then the design warnings.
    """
    d = design(optics)
    if short:
        return "\n".join([*_short_lines(d), *("⚠ " + w for w in design_warnings(optics))])
    rows = [
        ("Medium index n_medium (RI = n_medium + Δn)", f"{optics.medium_index:.4f}", ""),
        ("Elemental-image magnification M_EI", f"{d['m_ei']:.4g}", "x"),
        ("Object pixel size", f"{d['object_pixel_um']:.4f}", "µm"),
        ("Lenslet pitch on sensor", f"{d['pitch_px']:.2f}", "px"),
        ("EI radius R_EI (Eq. 8)", f"{d['ei_radius_um']:.1f} µm = {d['ei_radius_px']:.2f}", "px"),
        ("Iris radius at NIP (Eq. 9)", f"{d['iris_radius_um']:.1f}", "µm"),
        ("Field of view D_FOV (Eq. 10)", f"{d['fov_um']:.2f}", "µm"),
        ("Sub-aperture NA (object side)", f"{d['subaperture_na']:.4f}", ""),
        ("Coherence ratio sigma = NA_c / NA", f"{d['sigma']:.3f}", ""),
        ("Lateral resolution R_xy (Eq. 12)", f"{d['r_xy_um']:.2f}", "µm"),
        ("Axial resolution R_z, Eq. 13 as printed (tan = sqrt2 d/f_ml)", f"{d['r_z_printed_um']:.2f}", "µm"),
        (
            "Axial resolution R_z with tan = sqrt2 d/f_fl (matches paper's 20.6, measured 21.96)",
            f"{d['r_z_ffl_um']:.2f}",
            "µm",
        ),
        ("DOF, FWHM of central-lenslet PSF (Eq. 14)", f"{d['dof_fwhm_um']:.2f}", "µm"),
        ("DOF, full width (2 x FWHM)", f"{d['dof_full_um']:.2f}", "µm"),
        ("DOF, pitch-limited", f"{d['dof_pitch_um']:.1f}", "µm"),
        ("DOF, usable (smaller of the two)", f"{d['dof_um']:.2f}", "µm"),
        ("Lenslets overlapping the pupil", f"{d['lenslets_in_pupil']}", ""),
        ("Usable lenslets (>= 50% inside the pupil)", f"{d['lenslets_usable']}", ""),
        (
            "Lenslets inside / straddling / outside the source disk",
            f"{d['lenslets_inside']} / {d['lenslets_straddling']} / {d['lenslets_outside']}",
            "",
        ),
        ("Expected axial FWHM at this condenser NA", f"{d['expected_axial_fwhm_um']:.0f}", "µm"),
        ("Nyquist voxel, lateral (R_xy / 2)", f"{d['nyquist_voxel_xy_um']:.2f}", "µm"),
        ("Nyquist voxel, axial (R_z / 2)", f"{d['nyquist_voxel_z_um']:.2f}", "µm"),
    ]
    w = max(len(r[0]) for r in rows)
    lines = [f"{n:<{w}}  {v} {u}".rstrip() for n, v, u in rows]
    lines.append("Note: the paper's measured axial resolution (21.96 µm) matches the f_fl variant of R_z.")
    lines += [f"Warning: {w}" for w in design_warnings(optics)]
    return "\n".join(lines)


def _short_lines(d: dict) -> list[str]:
    """The main design numbers of :func:`design`'s ``d`` in a few lines narrow enough for a dock."""
    return [
        f"FOV {d['fov_um']:.1f} µm · R_xy {d['r_xy_um']:.2f} µm",
        f"R_z {d['r_z_ffl_um']:.2f} µm (tanθ = √2·d/f_fl: matches the",
        f"    paper's measured 21.96 µm); {d['r_z_printed_um']:.2f} µm with Eq. 13 as printed",
        f"DOF {d['dof_full_um']:.1f} µm full width (FWHM {d['dof_fwhm_um']:.1f} µm)",
        f"usable depth {d['dof_um']:.1f} µm",
        f"lenslets: {d['lenslets_in_pupil']} in the pupil, {d['lenslets_usable']} usable (≥ 50 % inside)",
        f"source disk: {d['lenslets_inside']} inside, {d['lenslets_straddling']} straddling, "
        f"{d['lenslets_outside']} outside",
        f"medium index {d['medium_index']:.4f} (RI = medium + Δn)",
        f"σ {d['sigma']:.2f} · M_EI {d['m_ei']:.3f} · object pixel {d['object_pixel_um']:.4f} µm",
        f"pitch {d['pitch_px']:.2f} px · EI radius {d['ei_radius_px']:.2f} px",
        f"expected axial FWHM {d['expected_axial_fwhm_um']:.1f} µm from the {d['lenslets_straddling']} "
        "lenslets that straddle the source edge",
    ]
