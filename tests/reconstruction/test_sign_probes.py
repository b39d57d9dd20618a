"""Sign 'auto': the two sign probes report progress against the settings' iterations and stop on Cancel."""

from __future__ import annotations

import numpy as np
import pytest

from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.physics.lattice import lenslet_case
from napari_ssdpc.reconstruction.forward import ViewModel, padded_planes
from napari_ssdpc.reconstruction.regularised import TvInversion
from napari_ssdpc.reconstruction.sign_probes import PROBE
from napari_ssdpc.settings.optics import Optics


@pytest.fixture(scope="module")
def problem():
    """A small TV problem (8 straddling views, 64 x 64 px, 11 planes) and noisy contrast of a blob."""
    optics = Optics.paper().replace(condenser_na=0.3)
    lenslets = [ln for ln in nominal_lenslets(optics) if lenslet_case(optics, ln) == "straddling"][:8]
    z = np.arange(-10.0, 10.1, 2.0)
    yy, xx = np.mgrid[:64, :64]
    mask = np.hypot(yy - 32, xx - 32) < 30
    zs, planes = padded_planes(z, 20.0)
    tv = TvInversion(ViewModel.for_lenslets(optics, lenslets, (64, 64), 0.8456, zs), planes, 20.0, mask=mask)
    rng = np.random.default_rng(0)
    contrast = (0.01 * (np.hypot(yy - 30, xx - 36) < 4) + rng.normal(0, 1e-3, (8, 64, 64))) * mask
    return tv, contrast.astype(np.float32)


def test_the_sign_probes_report_progress_against_the_settings_iterations(problem):
    tv, contrast = problem
    reports = []
    _, report = tv.phase(contrast, sign="auto", iterations=30, progress=lambda *r: reports.append(r), phi_max=1.0)
    assert reports[0] == (1, 30, "TV: probing the sign (denser)")  # from the first iteration on
    labels = [r[2] for r in reports]
    assert labels.count("TV: probing the sign (denser)") == labels.count("TV: probing the sign (lighter)") == PROBE
    best = report.sign.split()[1]
    final = [r for r in reports if r[2] == f"TV ({best})"]
    assert final[0][0] == PROBE + 1 and final[-1][0] == report.iterations <= 30  # the chosen sign's path
    assert {r[1] for r in reports} == {30}  # the total shown is the settings' iterations


def test_cancel_stops_the_sign_probes(problem):
    tv, contrast = problem
    reports = []
    stop = {"now": False}

    def progress(done, total, label):
        reports.append((done, total, label))
        stop["now"] = len(reports) >= 3

    tv.phase(contrast, sign="auto", iterations=60, tol=0.0, progress=progress, should_stop=lambda: stop["now"])
    assert len(reports) == 3  # stopped within the first probe: neither the second probe nor the solve ran on
