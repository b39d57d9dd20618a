"""A strong (silica-like) bead against the simulator's truth: 'tv', 'multislice' and ``ssdpc beads``
(slow; docs/nonlinear.md, docs/beads.md). The two fixtures share the module's simulated frames."""

import warnings

import numpy as np
import pytest

from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases as val
from napari_ssdpc.validation import truth as vt
from napari_ssdpc.validation.mass import mass_and_tail, masses_and_false
from napari_ssdpc.validation.truth import truth_volume

pytestmark = pytest.mark.slow


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
    region (the whole volume 1.12 x the truth before the rest of the frame was solved again; 2.94 x
    before the region's edge was held at the medium), the views explained to 2.7 x the noise (tv:
    267 x)."""
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


def test_multislice_strong_bead_false_dn_below_10_percent(silica):
    """docs/nonlinear.md: 0.054 x the bead's mass away from it, the rest of the frame solved by 'tv'
    once the region's model is taken out of the views (0.156 with the first 'tv' answer kept)."""
    assert silica["multislice"][1]["false"] < 0.1
    assert silica["multislice"][0].settings["multislice_rest_seconds"] > 0


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
