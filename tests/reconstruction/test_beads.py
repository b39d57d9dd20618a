"""The bead fit's search and fit on views its own model made: a bead the first answer puts too
shallow and too weak is found where it is, with its size and index; a frame without objects has
no beads."""

from dataclasses import replace

import numpy as np
import pytest

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.multislice_source import square_roi
from napari_ssdpc.reconstruction.bead_search import BeadRegion, wave_neighbours
from napari_ssdpc.reconstruction.beads import fit_beads
from napari_ssdpc.reconstruction.contrast import ViewContrast
from napari_ssdpc.reconstruction.fit_objects import bead_candidates
from napari_ssdpc.reconstruction.sphere_volume import spheres_volume
from napari_ssdpc.settings.reconstruction import MultisliceSettings

TRUTH = np.array([[1.2, -0.8, 2.5, 1.6, 0.045]])  # x, y, z, R (µm), Δn
NOISE = 0.003
#: a small region and few source points: the search and the fit, not the model's accuracy, are tested
SETTINGS = MultisliceSettings(roi_margin_um=10.0, source_spacing_na=0.06)


@pytest.fixture(scope="module")
def frame(synthetic_series):
    """The views of the bead by the model (with noise), and a first answer 3.5 µm too shallow at half its Δn."""
    optics, cal, flat, _, _ = synthetic_series
    contrast = ViewContrast(optics, cal, flat)
    shape = contrast.view_mask.shape
    roi = square_roi(contrast.x_um, contrast.y_um, tuple(TRUTH[0, :2]), 34.0)
    region = BeadRegion(contrast, np.ones(shape, np.float32), roi, -1.0, 6.0, 0.5, SETTINGS, None)
    m = region.model
    views = np.ones(shape, np.float32)
    views[:, roi[0], roi[1]] = m.views(spheres_volume(TRUTH, region.z_um, m.y_um, m.x_um, 0.5))
    views += np.random.default_rng(3).normal(0, NOISE, shape).astype(np.float32)
    z_um = np.arange(-8.0, 8.01, 1.0)
    first = TRUTH.copy()
    first[0, 2] -= 3.5
    first[0, 4] *= 0.5
    dn = spheres_volume(first, z_um, contrast.y_um, contrast.x_um, 1.0)
    return contrast, views, dn, z_um, optics


def test_the_candidates_are_the_objects_of_the_first_answer(frame):
    contrast, _, dn, z_um, _ = frame
    cands = bead_candidates(dn, z_um, contrast.y_um, contrast.x_um)
    assert cands.shape == (1, 5)
    assert cands[0, :3] == pytest.approx([1.2, -0.8, -1.0], abs=0.3)
    assert cands[0, 3] == pytest.approx(1.6, rel=0.35)
    _, elongation = bead_candidates(dn, z_um, contrast.y_um, contrast.x_um, return_elongation=True)
    assert elongation[0] < 1.1  # round: 1.06, a 3.2 µm sphere drawn on 0.85 µm pixels


def test_an_elongated_object_is_no_bead_where_round_ones_are_asked_for(frame):
    """An ellipsoid of axes 12 x 6 x 6 µm: its footprint's long axis is twice its short one, so a
    fit asked for round objects only leaves it (the multislice sphere start: cells are no beads)."""
    contrast, views, _, z_um, optics = frame
    zz, yy, xx = np.meshgrid(z_um, contrast.y_um, contrast.x_um, indexing="ij")
    dn = 0.02 * (((xx / 6.0) ** 2 + (yy / 3.0) ** 2 + (zz / 3.0) ** 2) <= 1.0)
    _, elongation = bead_candidates(dn, z_um, contrast.y_um, contrast.x_um, return_elongation=True)
    assert elongation == pytest.approx([2.0], rel=0.1)
    kw = {"noise": NOISE, "optics": optics, "settings": SETTINGS, "max_elongation": 1.3}
    assert fit_beads(contrast, views, dn, z_um, **kw) == []


@pytest.fixture(scope="module")
def found(frame):
    """The beads of the frame, searched for (no previous frame)."""
    contrast, views, dn, z_um, optics = frame
    optics = optics.replace(medium_index=1.333)
    return fit_beads(contrast, views, dn, z_um, noise=NOISE, optics=optics, settings=SETTINGS, z_search_um=5.0)


def test_a_bead_is_found_at_its_depth_size_and_index(found):
    assert len(found) == 1
    b = found[0]
    # the views were made on a larger region than the fit's: its periodic edge costs ~0.3 µm of depth here
    assert b.centre_um == pytest.approx(tuple(TRUTH[0, :3]), abs=0.5)
    assert b.diameter_um == pytest.approx(2 * TRUTH[0, 3], rel=0.03)
    assert b.delta_n == pytest.approx(TRUTH[0, 4], abs=0.002)
    assert b.ri == pytest.approx(1.333 + b.delta_n)
    assert b.explained and b.converged and b.note == ""
    # the check of the voxel answer: the first answer holds half the bead's Δn (3.5 µm off in depth)
    assert b.first_answer_ratio == pytest.approx(0.5, abs=0.05)


def test_beads_of_a_known_index_are_searched_over_size_and_depth(frame):
    """The fit of the optics gives the beads' index: the search holds it (a start one wave of phase
    off, with another Δn, is no longer among the starts) and finds the bead's size and depth."""
    contrast, views, dn, z_um, optics = frame
    optics = optics.replace(medium_index=1.333)
    kw = {"noise": NOISE, "optics": optics, "settings": SETTINGS, "z_search_um": 5.0}
    [b] = fit_beads(contrast, views, dn, z_um, delta_n=float(TRUTH[0, 4]), **kw)
    assert b.delta_n == TRUTH[0, 4]
    assert b.centre_um == pytest.approx(tuple(TRUTH[0, :3]), abs=0.5)
    assert b.diameter_um == pytest.approx(2 * TRUTH[0, 3], rel=0.03)
    assert b.explained and b.converged


def test_no_objects_no_beads_and_no_noise_is_refused(frame):
    contrast, views, dn, z_um, optics = frame
    kw = {"optics": optics, "settings": SETTINGS}
    assert fit_beads(contrast, views, np.zeros_like(dn), z_um, noise=NOISE, **kw) == []
    with pytest.raises(SsdpcError, match="noise"):
        fit_beads(contrast, views, dn, z_um, noise=0.0, **kw)


def test_two_beads_on_one_axis_leave_a_minimum_one_wave_away_together(synthetic_series):
    """Of two beads on one axis, the one nearer the objective one wave of phase too strong and 1.5 µm
    too near, the other 1.5 µm too far: among the starts one wave away (both moved at once) the
    truth is the best."""
    optics, cal, flat, _, _ = synthetic_series
    contrast = ViewContrast(optics, cal, flat)
    shape = contrast.view_mask.shape
    truth = np.array([[0.5, 0.3, -4.0, 1.6, 0.1], [0.5, 0.3, 4.0, 1.6, 0.1]])
    roi = square_roi(contrast.x_um, contrast.y_um, (0.5, 0.3), 24.0)
    region = BeadRegion(contrast, np.ones(shape, np.float32), roi, -12.0, 12.0, 1.0, SETTINGS, None)
    m = region.model
    views = np.ones(shape, np.float32)
    views[:, roi[0], roi[1]] = m.views(spheres_volume(truth, region.z_um, m.y_um, m.x_um, 1.0))
    region = BeadRegion(contrast, views, roi, -12.0, 12.0, 1.0, SETTINGS, None)
    wave = optics.wavelength_um / (2 * 1.6)
    wrong = truth.copy()
    wrong[0, 2:5:2] += (-1.5, wave)
    wrong[1, 2] += 1.5
    found = wave_neighbours(region, wrong, np.ones(2), optics.wavelength_um, (-12.0, 12.0))
    assert len(found) == 15 * 10  # the lower bead's Δn one wave down, kept or up; the upper's not below 0
    best = min(found, key=lambda a: a[0])[1]
    np.testing.assert_allclose(best, truth, atol=1e-6)
    # a centre never leaves the volume's planes (z −5..5 µm here: two depths of each bead's five are in)
    inside = wave_neighbours(region, wrong, np.ones(2), optics.wavelength_um, (-5.0, 5.0))
    assert len(inside) == (2 * 3) * (2 * 2) and all(np.abs(p[:, 2]).max() <= 5.0 for _, p in inside)


def test_a_series_fits_its_beads_from_the_previous_frames(frame, found):
    """The bead of the previous frame (here the bead found, moved by 0.7 µm, Δn 10 % off) is the
    start of the full fit, without the scan. When that fit explains the views much worse than the
    previous frame's did (here the previous bead said to be explained to the noise: the frame's
    bead may have settled in another minimum), it is not kept and the bead is searched for as in
    a first frame; a previous bead of the other sign is another object."""
    contrast, views, dn, z_um, optics = frame
    kw = {"optics": optics.replace(medium_index=1.333), "settings": SETTINGS, "z_search_um": 5.0}
    [bead] = found
    x, y, z, r, d = TRUTH[0]
    cases = (
        ((-0.4, 0.3, -0.5), 1.1 * d, bead.residual_over_noise, False),
        ((0.0, 0.0, 0.0), d, 1.0, True),
        ((0.0, 0.0, 0.0), -d, bead.residual_over_noise, True),
    )
    for shift, dn_before, residual_before, searched in cases:
        moved = tuple(c + s for c, s in zip(bead.centre_um, shift, strict=True))
        before = replace(bead, centre_um=moved, delta_n=dn_before, residual_over_noise=residual_before)
        stages: list[str] = []
        [b] = fit_beads(contrast, views, dn, z_um, noise=NOISE, previous=[before], progress=_recorder(stages), **kw)
        assert b.centre_um == pytest.approx(tuple(TRUTH[0, :3]), abs=0.5)
        assert b.delta_n == pytest.approx(d, abs=0.002) and b.diameter_um == pytest.approx(2 * r, rel=0.03)
        assert b.explained and b.note == ""
        assert any("scanning" in s for s in stages) == searched, stages


def _recorder(stages: list):
    """A progress callback that records the stages' labels."""
    return lambda done, total, label: stages.append(label)
