"""Accuracy against the simulator's ground truth (slow: full-size simulations at condenser NA 0.3).

Targets from the pipeline issue; the measured numbers are in docs/validation.md. A target the
physics does not reach is an xfail with the measured number, strict so that it is noticed when
it starts to pass.
"""

import os
import warnings

import numpy as np
import pytest

from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt
from napari_ssdpc.validation.mass import mass_and_tail, masses_and_false
from napari_ssdpc.validation.truth import truth_volume

pytestmark = pytest.mark.slow

#: The module's fixtures, the longest first (setup on 2 cores: 708, 568, 351, 336, about 300, 248,
#: 236, 228 s): CI's slow run starts them first on its workers (tests/conftest.py).
SLOWEST_FIRST = ("stacked", "silica", "cell", "bead", "two_beads", "weak_bead", "cache", "silica_bead")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """Simulated frames: SSDPC_VALIDATION_CACHE keeps them between runs (same files as
    docs/compare_methods.py --cache)."""
    return os.environ.get("SSDPC_VALIDATION_CACHE") or tmp_path_factory.mktemp("validation")


@pytest.fixture(scope="module")
def bead(cache):
    case = val.simulate_case("bead", ph.pmma_bead(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, stacks=False)  # the default method, 'tv'
    assert res.settings["method"] == "tv" and res.settings["tv_sign"].startswith("auto: lighter")
    return vt.bead_metrics(res, case.phantom, 1.518)


@pytest.fixture(scope="module")
def two_beads(cache):
    # the condenser sampled every 4th lattice step: 3.2x faster to simulate (234 s against 842 s on
    # 2 cores), the same answer (depths within 0.03 µm, peaks within 2 % of the finer sampling's)
    case = val.simulate_case("two-beads", ph.two_beads(), val.paper_optics(), cache_dir=cache, source_step=4)
    res, _, _ = val.reconstruct_case(case, stacks=False)
    assert res.settings["tv_sign"].startswith("auto: denser")
    return [vt.bead_metrics(res, s, 1.518) for s in case.phantom.spheres], case.phantom.spheres


@pytest.fixture(scope="module")
def weak_bead(cache):
    bead = ph.weak_bead()
    case = val.simulate_case("weak-bead", bead, val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(-40, 40), stacks=False)
    return {
        **vt.bead_metrics(res, bead, 1.518),
        **vt.projected_phase_metrics(res, bead, 1.518, case.optics.wavelength_um),
        **vt.truth_metrics(res, bead, 1.518, (20.7, 3.9)),
    }


def test_weak_bead_projected_phase_within_10_percent(weak_bead):
    """The 2D number first: a 0.5 rad bead's projected phase, over its footprint and at its centre."""
    assert weak_bead["phase_footprint_ratio"] == pytest.approx(1.0, abs=0.1)  # measured 1.01
    assert weak_bead["phase_centre_ratio"] == pytest.approx(1.0, abs=0.1)  # measured 0.94


def test_weak_bead_found_at_its_depth(weak_bead):
    cx, cy, cz = weak_bead["centroid_um"]
    assert abs(cz - 10.0) < 2.0 and np.hypot(cx, cy) < 1.0  # measured 0.17 µm deep, 0.02 µm aside
    assert weak_bead["dn_peak"] > 0.3 * 0.007  # measured 0.50 of the true Δn (wotf 0.33)


def test_pmma_bead_is_negative_and_in_place(bead):
    assert bead["dn_centre"] < 0 and bead["dn_peak"] < 0
    cx, cy, cz = bead["centroid_um"]
    assert np.hypot(cx, cy) < 1.0  # lateral centroid within 1 µm
    assert abs(cz) < 2.0  # axial centroid within 2 µm (measured +1.7 µm; Tikhonov: +3.2 µm)


def test_pmma_bead_peak_is_at_least_half_the_truth(bead):
    assert bead["dn_peak"] < 0.5 * -0.028  # measured −0.021 (Tikhonov: −0.0075)


@pytest.mark.xfail(
    strict=True,
    reason="measured: Δn summed along z through the centre 1.36 x the true optical path (the missing cone's tails)",
)
def test_pmma_bead_optical_path_within_10_percent(bead):
    assert bead["opd_ratio"] == pytest.approx(1.0, rel=0.1)


def test_pmma_bead_lateral_fwhm_within_20_percent(bead):
    assert bead["fwhm_x_um"] == pytest.approx(13.0, rel=0.2)  # measured 10.8 µm (Tikhonov 10.2 µm)
    assert bead["fwhm_y_um"] == pytest.approx(13.0, rel=0.2)


def test_pmma_bead_axial_fwhm_is_between_the_bead_and_the_papers(bead):
    # the bead is 13 µm long; the paper measured 21.96 µm; measured 14.4 µm (Tikhonov 21 µm)
    assert 13.0 < bead["fwhm_z_um"] < 22.0


def test_two_beads_found_at_their_depths(two_beads):
    metrics, spheres = two_beads
    for m, s in zip(metrics, spheres):
        cx, cy, cz = m["centroid_um"]
        x, y, z = s.center_um
        assert abs(cz - z) < 2.0  # measured 1.07 and 0.69 µm
        assert np.hypot(cx - x, cy - y) < 1.0
        assert m["dn_peak"] > 0.5 * 0.042  # measured 0.026 and 0.029 (Tikhonov 0.008)


@pytest.fixture(scope="module")
def cell(cache):
    case = val.simulate_case("cell", ph.cell(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(-40, 40), stacks=False)
    return vt.cell_metrics(res, case.phantom, (20.7, 3.9))


@pytest.mark.xfail(
    strict=True, reason="measured: correlation 0.862 with the blurred truth (Tikhonov 0.566; 0.902 at NA 0.25)"
)
def test_cell_correlates_with_the_truth_at_the_system_resolution(cell):
    assert cell["correlation_blurred"] >= 0.9  # the target


def test_cell_nucleus_ri_matches_the_blurred_truth(cell):
    assert abs(cell["ri_nucleus"] - cell["ri_nucleus_blurred_truth"]) < 0.01  # measured 0.006


def test_bar_target_resolved_at_its_depth(cache):
    case = val.simulate_case("bars", ph.bar_target(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(0, 80), method="rl", stacks=True)
    m = vt.bar_metrics(res, case.phantom)
    assert abs(m["best_focus_z_um"] - case.phantom.z_um) < 5.0  # measured 38 µm
    for period in (8.76, 6.2, 4.92):
        assert m["contrast"][period] > 0.10  # measured 1.0, 1.0, 0.13


@pytest.mark.xfail(
    strict=True,
    reason="measured contrast -0.01 at 15 RL iterations (0.09 at 40): 4.38 µm is "
    "at the sub-aperture cutoff (R_xy 3.9 µm)",
)
def test_bar_target_finest_element_resolved(cache):
    case = val.simulate_case("bars", ph.bar_target(), val.paper_optics(), cache_dir=cache)
    res, _, _ = val.reconstruct_case(case, z=(0, 80), method="rl", stacks=True)
    assert vt.bar_metrics(res, case.phantom)["contrast"][4.38] > 0.10


@pytest.fixture(scope="module")
def silica(cache):
    """A silica-like 5 µm bead in water (Δn +0.13, 7.9 rad through its centre) at condenser NA 0.25,
    reconstructed with 'tv' and with 'multislice' (with the warnings each gave)."""
    sphere = ph.Sphere((0.0, 0.0, 0.0), 5.0, 1.463, medium_index=1.333)
    case = val.simulate_case("silica-5um", sphere, val.paper_optics(0.25), cache_dir=cache)
    out, rec = {}, None
    for method in ("tv", "multislice"):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if rec is None:
                res, _, rec = val.reconstruct_case(case, z=(-30, 30), method=method)
            else:  # the refinement of the same frame starts from the tv answer just computed
                assert rec.adopt(val.run_config(case.optics, z=(-30, 30), method=method))
                res = rec.reconstruct(case.frame)
        said = [str(w.message) for w in caught]
        m = mass_and_tail(res, sphere, 1.333)
        m.update(masses_and_false(res, [sphere], 1.333))
        m["whole"] = float(res.delta_n.sum() / truth_volume(sphere, res, 1.333).sum())
        out[method] = (res, m, vt.bead_metrics(res, sphere, 1.333), said)
    return out


def test_multislice_keeps_a_strong_beads_mass_where_tv_loses_it(silica):
    """docs/nonlinear.md: integrated Δn 0.97 x the truth with 'multislice' against 0.18 x with 'tv'
    (which warns and names the method), its depth within 1 µm (measured +0.05), no floor over its
    region (the whole volume 1.12 x the truth; 2.94 x before the region's edge was held at the
    medium), the views explained to 2.7 x the noise (tv: 267 x)."""
    tv, ms = silica["tv"], silica["multislice"]
    assert tv[1]["integrated"] < 0.5  # the first-order model loses most of the mass
    assert any("--method multislice" in m for m in tv[3])
    assert not any("--method multislice" in m for m in ms[3])
    assert ms[1]["integrated"] > 2 * tv[1]["integrated"]
    assert abs(ms[2]["centroid_um"][2]) < 1.0
    assert 0.5 < ms[1]["whole"] < 1.2  # no floor over the model's region
    s = ms[0].settings
    assert s["multislice_residual_over_noise"] < 5 < tv[0].settings["tv_residual_over_noise"] / 10
    bead = s["multislice_objects"][0]  # the largest
    assert np.allclose(bead["centre_um"][:2], 0.0, atol=0.5) and abs(bead["centre_um"][2]) < 1.5


def test_multislice_strong_bead_mass_within_10_percent_and_no_tail(silica):
    """docs/nonlinear.md: the start from the bead fitted as a sphere, kept (it explains the views to
    the stop): 0.97 x the integrated Δn, tail 0.00 (from the 'tv' start: 0.64, tail 0.37)."""
    m, s = silica["multislice"][1], silica["multislice"][0].settings
    assert s["multislice_start"].startswith("spheres")
    assert abs(m["integrated"] - 1.0) < 0.1 and m["tail"] < 0.1


@pytest.mark.xfail(
    strict=True,
    reason="measured 0.16 x the bead's mass: the 'tv' answer kept outside the model's region (15-25 µm "
    "from the axis 0.08, beyond 0.08; docs/nonlinear.md)",
)
def test_multislice_strong_bead_false_dn_below_10_percent(silica):
    assert silica["multislice"][1]["false"] < 0.1


@pytest.fixture(scope="module")
def stacked(cache):
    """Two silica-like 5 µm beads in water on one axis, at z −12 and +12 µm, with 'multislice' on
    z −20..20 µm."""
    beads = [ph.Sphere((0.0, 0.0, z), 5.0, 1.463, medium_index=1.333) for z in (-12.0, 12.0)]
    case = val.simulate_case(
        "stacked-silica", ph.Spheres(beads, medium_index=1.333), val.paper_optics(0.25), cache_dir=cache
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res, _, _ = val.reconstruct_case(case, z=(-20, 20), method="multislice")
    return res, masses_and_false(res, beads, 1.333)


def test_multislice_keeps_both_beads_on_one_axis(stacked):
    """docs/validation.md: 1.00 and 0.97 x each bead's mass near it (on z −30..30 µm the bead above
    held 0.22 x, all of it floor, when the model kept one depth window per footprint), over every
    plane."""
    res, m = stacked
    assert min(m["masses"]) > 0.3
    assert res.settings["multislice_z_um"] == [-20.0, 20.0]


def test_multislice_stacked_beads_each_within_15_percent(stacked):
    """docs/validation.md: both beads fitted as spheres, the start kept: 1.00 and 0.97 x each bead's
    mass, depths +0.05 and +0.04 µm (from the 'tv' start: 0.54 and 0.62, ±1.5 µm, joined)."""
    res, m = stacked
    assert all(abs(v - 1) < 0.15 for v in m["masses"])
    assert all(abs(d) < 1.0 for d in m["centroids_z_um"])
    assert len(res.settings["multislice_objects"]) == 2


@pytest.mark.xfail(
    strict=True,
    reason="measured 0.12 x the beads' mass: the 'tv' answer kept outside the model's region (docs/validation.md)",
)
def test_multislice_stacked_false_dn_below_10_percent(stacked):
    assert stacked[1]["false"] < 0.1


@pytest.fixture(scope="module")
def silica_bead(cache, tmp_path_factory):
    """``ssdpc beads --json`` on the silica-like 5 µm bead in water (7.9 rad), from one frame."""
    import contextlib
    import io
    import json

    import tifffile

    from napari_ssdpc.calibration import calibrate
    from napari_ssdpc.cli.main import main

    d = tmp_path_factory.mktemp("silica-bead")
    sphere = ph.Sphere((0.0, 0.0, 0.0), 5.0, 1.463, medium_index=1.333)
    case = val.simulate_case("silica-5um", sphere, val.paper_optics(0.25), cache_dir=cache)
    tifffile.imwrite(d / "raw.tif", case.frame)
    tifffile.imwrite(d / "flat.tif", case.flat)
    calibrate(case.white, case.optics).to_json(d / "cal.json")
    argv = ["beads", d / "raw.tif", "--calibration", d / "cal.json", "--flat", d / "flat.tif", "--z", "-30", "30"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([str(a) for a in [*argv, "--json"]]) == 0
    return json.loads(out.getvalue())["beads"]


def test_ssdpc_beads_measures_a_strong_bead_where_it_is_and_its_size(silica_bead):
    """docs/beads.md: measured centre within 0.05 µm, diameter −1.8 % (targets 0.5 µm, 3 %), the model
    explaining the views over it."""
    assert len(silica_bead) == 1
    b = silica_bead[0]
    assert np.linalg.norm(b["centre_um"]) < 0.5
    assert abs(b["diameter_um"] / 5.0 - 1) < 0.03
    assert b["explained"] and b["converged"]


@pytest.mark.xfail(
    strict=True,
    reason="measured RI +0.0021 for the ± 0.002 target: the model's error splits the bead's phase "
    "between radius (−1.8 %) and Δn (docs/beads.md)",
)
def test_ssdpc_beads_measures_a_strong_bead_to_its_index(silica_bead):
    assert abs(silica_bead[0]["ri"] - 1.463) < 0.002
