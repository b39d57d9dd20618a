"""Reconstruction pipeline: numbers on a simulated weak bead, both phase methods, bad input."""

import dataclasses
import re

import numpy as np
import pytest
import tifffile

from napari_ssdpc.cli.main import main
from napari_ssdpc.errors import Cancelled, SsdpcError, SsdpcWarning
from napari_ssdpc.reconstruction.frame_result import z_grid
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.simulation import phantoms
from napari_ssdpc.validation import metrics as an
from napari_ssdpc.validation.cases import run_config, simulate_case
from napari_ssdpc.validation.truth import truth_volume

BEAD = phantoms.Sphere((4.0, -3.0, 0.0), 6.0, 1.528, medium_index=1.518)  # weak: 0.7 rad through the centre


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    from napari_ssdpc.settings.optics import Optics

    return simulate_case("weak-bead-test", BEAD, Optics.paper(), cache_dir=tmp_path_factory.mktemp("sim"))


@pytest.fixture(scope="module")
def calibration(case):
    from napari_ssdpc.calibration import calibrate

    return calibrate(case.white, case.optics)


@pytest.fixture(scope="module")
def reconstructor(case, calibration):
    config = run_config(case.optics, z=(-30, 30), dz=2, rl={"iterations": 8})
    return Reconstructor(config, calibration, flat=case.flat, stacks=True)


@pytest.fixture(scope="module")
def result(case, reconstructor):
    return reconstructor.reconstruct(case.frame)


def test_weak_bead_sign_position_and_optical_path(result):
    dn = result.delta_n
    coords = (result.z_um, result.y_um, result.x_um)
    iz, iy, ix = (int(np.argmin(abs(c - v))) for c, v in zip(coords, (0.0, -3.0, 4.0)))
    assert dn[iz, iy, ix] > 0  # n 1.528 > 1.518
    cz, cy, cx = an.centroid(dn, coords, sign=1)
    assert abs(cx - 4.0) < 1.0 and abs(cy + 3.0) < 1.0  # lateral centroid within 1 µm
    # the z-integrated Δn through the centre is the bead's optical path difference (0.01 x 6 µm)
    opd = dn[:, iy, ix].sum() * result.voxel_um[0]
    assert opd == pytest.approx(0.06, rel=0.25)


def test_result_has_coordinates_and_all_outputs(result, reconstructor):
    # the views span the EI diameter (~145 px at 0.8456 µm): the whole 122.5 µm field of view
    assert result.ri.shape == (31, len(result.y_um), len(result.x_um)) and 141 <= len(result.x_um) <= 147
    assert result.voxel_um == pytest.approx((2.0, 0.8456, 0.8456), rel=1e-3)
    assert result.ri.dtype == np.float32 and np.all(np.isfinite(result.ri))
    assert set(result.stacks) == {"up", "down", "left", "right"} and set(result.dpc) == {"ud", "lr"}
    assert result.absorption.shape == result.ri.shape
    for half in ("up", "down", "left", "right"):  # RL records the relative change per iteration
        h = result.convergence[half]
        assert len(h) == 8 and h[-1] < h[0]
    tv = result.convergence["tv"]  # the TV solve: its objective falls from the Tikhonov start
    assert len(tv["objective"]) == result.settings["tv_iterations_run"] and tv["objective"][-1] < tv["objective"][0]
    # 2D maps: OPD = Σ Δn dz (nm) and dry mass = OPD / 0.19 µm³/pg
    assert result.opd_nm.shape == result.ri.shape[1:]
    np.testing.assert_allclose(result.opd_nm, 2e3 * result.delta_n.sum(axis=0), rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(result.dry_mass, result.opd_nm * 1e-3 / 0.19, rtol=1e-5, atol=1e-6)
    assert len(reconstructor.lenslets) == 4  # sigma 0.25: only the central lenslets get direct light


def test_paper_route_finds_the_bead_with_the_right_sign(case, calibration):
    config = run_config(case.optics, z=(-30, 30), dz=2, rl={"iterations": 8}, method="rl")
    rec = Reconstructor(config, calibration, flat=case.flat)
    res = rec.reconstruct(case.frame)
    truth = truth_volume(BEAD, res, 1.518, blur_um=(40.0, 3.9))
    assert an.correlation(res.delta_n, truth) > 0.5


def test_cancel_stops_within_an_iteration(case, reconstructor):
    calls = []

    def stop():
        calls.append(1)
        return len(calls) >= 2

    with pytest.raises(Cancelled):
        reconstructor.reconstruct(case.frame, should_stop=stop)
    assert len(calls) == 2


def test_bad_frames(case, reconstructor):
    with pytest.raises(SsdpcError, match="differs from the calibration"):
        reconstructor.reconstruct(case.frame[:-8])
    bad = case.frame.astype(np.float32)
    bad[100, 100] = np.nan
    with pytest.raises(SsdpcError, match="non-finite|NaN"):
        reconstructor.reconstruct(bad)
    sat = case.frame.copy()
    sat[sat > np.percentile(sat, 99)] = 4095
    with pytest.warns(SsdpcWarning, match="saturated"):
        reconstructor.reconstruct(sat)


def test_bad_settings(case, calibration):
    with pytest.raises(SsdpcError, match="dz must be > 0"):
        z_grid(-10, 10, 0)
    with pytest.raises(SsdpcError, match="'rl.iterations' must be positive"):
        run_config(case.optics, z=(-10, 10), dz=2, rl={"iterations": 0})
    with pytest.warns(SsdpcWarning, match="beyond the depth of field"):
        Reconstructor(run_config(case.optics, z=(-200, -190), dz=5), calibration, flat=case.flat)
    with pytest.raises(SsdpcError, match="takes a RunConfig"):
        Reconstructor(case.optics, calibration)
    with pytest.raises(SsdpcError, match="takes a Calibration"):
        Reconstructor(run_config(case.optics), "calibration.json")
    for dark in (float("nan"), -5.0, float("inf"), "100"):
        with pytest.raises(SsdpcError, match="dark offset in camera units"):
            Reconstructor(run_config(case.optics, z=(-10, 10), dz=2), calibration, dark=dark)
    for light in (0.0, 2.0, float("nan")):
        with pytest.raises(SsdpcError, match="fraction of the brightest lenslet's light"):
            Reconstructor(run_config(case.optics, z=(-10, 10), dz=2), calibration, min_light=light)


def test_cli_reconstruct_writes_ome_tiff_and_keeps_outputs_on_error(case, calibration, tmp_path, capsys):
    for name in ("frame", "flat"):
        tifffile.imwrite(tmp_path / f"{name}.tif", getattr(case, name))
    calibration.to_json(tmp_path / "cal.json")
    out = tmp_path / "out.ome.tif"
    args = [
        "reconstruct",
        str(tmp_path / "frame.tif"),
        "--calibration",
        str(tmp_path / "cal.json"),
        "--flat",
        str(tmp_path / "flat.tif"),
        "--z",
        "-20",
        "20",
        "--dz",
        "4",
        "--iterations",
        "3",
    ]
    assert main(args + ["--save", "phase", "-o", str(out)]) == 0
    with tifffile.TiffFile(out) as tif:
        assert tif.series[0].axes == "ZYX" and tif.series[0].shape[0] == 11
        px = tif.ome_metadata
        assert 'PhysicalSizeZ="4.0"' in px and 'PhysicalSizeX="0.845588' in px
    assert (tmp_path / "out_phase.ome.tif").is_file()
    before = out.read_bytes()
    capsys.readouterr()
    for bad, words in (
        (["--dz", "0"], "'dz_um' must be positive"),
        (["--iterations", "0"], "'rl.iterations' must be positive"),
    ):
        assert main(args + bad + ["-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1
    assert (
        main(
            ["reconstruct", str(tmp_path / "missing.tif"), "--calibration", str(tmp_path / "cal.json"), "-o", str(out)]
        )
        == 2
    )
    assert "file not found" in capsys.readouterr().err
    assert out.read_bytes() == before  # the good output is untouched


def test_every_method_runs_on_a_device_backend(case, calibration, result):
    """With a backend that keeps CuPy's rules (tests/fake_device.py: no host array may meet a device
    array), RL, the DPC stacks, the Tikhonov warm start and the TV solve give the CPU's numbers:
    what runs on a GPU is the same code."""
    from fake_device import fake_gpu

    config = run_config(case.optics, z=(-30, 30), dz=2, rl={"iterations": 8})
    rec = Reconstructor(config, calibration, flat=case.flat, stacks=True, backend=fake_gpu())
    assert rec.backend.is_gpu and rec.method.tv.model.bk is rec.backend
    dev = rec.reconstruct(case.frame)
    assert dev.settings["method"] == result.settings["method"] == "tv"
    assert isinstance(dev.delta_n, np.ndarray) and isinstance(dev.stacks["up"], np.ndarray)
    peak = float(np.abs(result.delta_n).max())
    assert peak > 0 and np.max(np.abs(dev.delta_n - result.delta_n)) <= 1e-4 * peak
    for h in result.stacks:
        np.testing.assert_allclose(dev.stacks[h], result.stacks[h], rtol=1e-4, atol=1e-6 * result.stacks[h].max())
    assert dev.settings["tv_iterations_run"] == result.settings["tv_iterations_run"]


def test_multislice_refines_the_tv_solution_of_a_weak_bead(case, calibration, result):
    """The multislice method starts from tv; on a weak object (0.7 rad) tv already explains the views
    to within the noise, so it stops there (the discrepancy principle) and keeps tv's answer: the
    bead's optical path and position. Asked to go on, it lowers the misfit."""
    config = run_config(case.optics, z=(-30, 30), dz=2, method="multislice", multislice={"iterations": 6})
    res = Reconstructor(config, calibration, flat=case.flat).reconstruct(case.frame)
    s = res.settings
    iy, ix = int(np.argmin(abs(res.y_um + 3.0))), int(np.argmin(abs(res.x_um - 4.0)))
    opd = lambda r: r.delta_n[:, iy, ix].sum() * r.voxel_um[0]
    assert s["method"] == "multislice" and s["multislice_converged"]
    assert s["multislice_residual_over_noise"] <= 4.0
    # the descent from 'tv', its region's own answer (the rest of the frame not solved again)
    more = {"iterations": 3, "stop_residual_over_noise": 0.0, "sphere_start": False, "rest_of_frame": False}
    config = run_config(case.optics, z=(-30, 30), dz=2, method="multislice", multislice=more)
    with pytest.warns(SsdpcWarning, match=r"did not converge in 3 iterations.*--multislice-iterations"):
        pushed_res = Reconstructor(config, calibration, flat=case.flat).reconstruct(case.frame)
    pushed = pushed_res.settings
    assert pushed["multislice_iterations_run"] == 3 and not pushed["multislice_converged"]
    # then held to its objects grown by 3 µm: the bead stays, the Δn spread elsewhere goes back to the medium
    config = run_config(
        case.optics, z=(-30, 30), dz=2, method="multislice", multislice={**more, "support_margin_um": 3.0}
    )
    with pytest.warns(SsdpcWarning, match="did not converge"):
        held = Reconstructor(config, calibration, flat=case.flat).reconstruct(case.frame)
    assert held.settings["multislice_iterations_run"] > 3
    assert opd(held) == pytest.approx(opd(pushed_res), rel=0.25)
    r0, r1, c0, c1 = pushed["multislice_roi_px"]
    assert held.settings["multislice_roi_px"] == pushed["multislice_roi_px"]
    spread = [np.count_nonzero(r.delta_n[:, r0:r1, c0:c1]) for r in (pushed_res, held)]
    assert spread[1] < 0.5 * spread[0], spread
    assert pushed["multislice_objective_final"] < pushed["multislice_objective_start"]
    # the unknowns on the model's finer grid: the same descent, the result back on the views' grid
    config = run_config(case.optics, z=(-30, 30), dz=2, method="multislice", multislice={**more, "unknowns": "model"})
    fine = Reconstructor(config, calibration, flat=case.flat).reconstruct(case.frame)
    assert fine.delta_n.shape == res.delta_n.shape
    assert fine.settings["multislice_objective_final"] < fine.settings["multislice_objective_start"]
    assert opd(fine) == pytest.approx(opd(res), rel=0.25)
    r0, r1, c0, c1 = s["multislice_roi_px"]
    assert r1 - r0 == c1 - c0 and 0 <= r0 and r1 <= len(res.y_um)  # a square region inside the field
    x, y = res.x_um[(c0 + c1) // 2], res.y_um[(r0 + r1) // 2]
    assert abs(x - 4.0) < 8.0 and abs(y + 3.0) < 8.0  # around the bead at (4, -3) µm
    assert opd(res) == pytest.approx(opd(result), rel=0.25) and opd(res) == pytest.approx(0.06, rel=0.3)
    with pytest.raises(SsdpcError, match="outside the field of view"):
        roi = run_config(case.optics, z=(-30, 30), dz=2, method="multislice", multislice={"roi_um": [500, 520, 0, 20]})
        Reconstructor(roi, calibration, flat=case.flat).reconstruct(case.frame)


def test_tv_names_the_multislice_method_beyond_the_first_order_regime(case, reconstructor, result, monkeypatch):
    """'tv' reports the phase through its strongest object (Σ_z φ): the weak bead's 0.72 rad lies
    well inside the first-order regime and nothing is said; past ``STRONG_PHASE_RAD`` (1.2 rad,
    docs/nonlinear.md) the warning gives the phase and the residual and names the method to use."""
    from napari_ssdpc.reconstruction.methods import tv

    through = result.settings["tv_phase_through_rad"]
    assert through == pytest.approx(2 * np.pi * 0.01 * 6.0 / case.optics.wavelength_um, rel=0.3)
    assert through < tv.STRONG_PHASE_RAD
    monkeypatch.setattr(tv, "STRONG_PHASE_RAD", through / 2)
    with pytest.warns(SsdpcWarning, match=r"delays the light by 0\.\d rad .* --method multislice"):
        reconstructor.reconstruct(case.frame)


@pytest.mark.parametrize("flat_na", [0.2, 0.3])
def test_a_flat_at_another_condenser_na_is_refused(case, calibration, flat_na):
    """A flat recorded at another condenser NA than the frames (here 0.2 or 0.3 for frames at 0.1)
    gave Δn up to the clip; its lenslets' light shows the NA it was recorded at (the overlap of
    condenser disk and sub-aperture), and so do the raw frames'."""
    from napari_ssdpc.reconstruction import consistency
    from napari_ssdpc.simulation.sample_free import flat_frame

    optics = case.optics.replace(condenser_na=flat_na)
    other = flat_frame(optics, grid=case.grid, rng=np.random.default_rng(1))
    config = run_config(case.optics, z=(-30, 30), dz=2)
    with pytest.raises(SsdpcError, match=rf"flat frame: its lenslets are lit as by a condenser NA of about {flat_na}"):
        Reconstructor(config, calibration, flat=other)
    rec = Reconstructor(config, calibration, flat=case.flat)  # the right flat passes
    levels, _, _ = rec.views._measure(case.frame, "frame")
    na, excess, _ = consistency.apparent_condenser_na(levels, calibration.lenslets, case.optics)
    assert na == pytest.approx(0.1, abs=0.002) and excess < 1
    with pytest.raises(
        SsdpcError, match=rf"frame: .* condenser NA of about (0\.\d+), but the optics say {flat_na}"
    ) as e:
        Reconstructor(run_config(optics, z=(-30, 30), dz=2), calibration).reconstruct(case.frame)
    assert float(e.value.args[0].split("about ")[1].split(",")[0]) == pytest.approx(0.1, abs=0.002)


@pytest.mark.parametrize("flat_na, refused", [(0.11, False), (0.12, True)])
def test_a_flat_a_few_per_cent_off_the_condenser_na(case, calibration, flat_na, refused):
    """A condenser NA 5 % off the optics' moved a bead's peak Δn by 21 % (10 %: 44 %) with exit 0
    (condenser NA 0.3). Here, at 0.1, the NA measured from the flat is within 0.001 of the truth and
    one 10 % off is reported with it, one 20 % off refused; the right flat is neither."""
    import warnings

    from napari_ssdpc.simulation.sample_free import flat_frame

    other = flat_frame(case.optics.replace(condenser_na=flat_na), grid=case.grid, rng=np.random.default_rng(2))
    config = run_config(case.optics, z=(-30, 30), dz=2)
    if refused:
        with pytest.raises(
            SsdpcError, match=r"flat frame: .* condenser NA of about 0\.1[12]\d, but the optics say 0\.1;"
        ):
            Reconstructor(config, calibration, flat=other)
    else:
        with pytest.warns(SsdpcWarning, match=r"flat frame: .* condenser NA of 0\.1(09|10|11), the optics say 0\.1: "):
            rec = Reconstructor(config, calibration, flat=other)
        assert rec.settings()["condenser_na_seen"] == pytest.approx(flat_na, abs=0.0015)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SsdpcWarning)
        rec = Reconstructor(config, calibration, flat=case.flat)
    assert rec.settings()["condenser_na_seen"] == pytest.approx(0.1, abs=0.0015)


@pytest.mark.parametrize("scale", [0.5, 1.5, 4.0])
def test_an_exposure_change_is_normalised_and_reported(case, reconstructor, result, scale):
    """The raw frame at half, 1.5x or 4x the flat's exposure scaled Δn with it (truth unchanged); its
    views are normalised to the flat's level, the factor is reported and kept in the metadata."""
    dark = 100.0  # the simulated camera's offset, ADU
    frame = np.clip((case.frame.astype(np.float64) - dark) * scale + dark, 0, 65535).astype(np.uint16)
    with pytest.warns(SsdpcWarning, match=rf"is {scale:.2f} x as bright as the flat frame"):
        res = reconstructor.reconstruct(frame)
    assert res.settings["exposure_ratio"] == pytest.approx(scale, rel=0.03)
    assert result.settings["exposure_ratio"] == pytest.approx(1.0, abs=0.02)
    peak = float(np.abs(result.delta_n).max())
    assert float(np.abs(res.delta_n - result.delta_n).max()) < 0.15 * peak


def test_the_sample_frame_given_as_the_flat_is_refused(case, calibration):
    config = run_config(case.optics, z=(-30, 30), dz=2)
    with pytest.raises(SsdpcError, match="frame equals the flat frame"):
        Reconstructor(config, calibration, flat=case.frame).reconstruct(case.frame)


@pytest.mark.parametrize("shift", [(3, 0), (-2, 10)])
def test_a_moved_camera_or_an_edited_calibration_is_refused(case, calibration, reconstructor, shift):
    """The elemental images of a frame shifted after calibration (the camera moved), or of a
    calibration whose centres were edited, sit away from where it puts them: measured to 0.05 px
    from the disks' cross-correlation, refused beyond 1.5 px."""
    from napari_ssdpc.reconstruction import consistency

    dx, dy = shift
    moved = np.roll(case.frame, (dy, dx), axis=(0, 1))
    assert consistency.ei_shift_px(case.frame, reconstructor.views._ei) == pytest.approx((0, 0), abs=0.1)
    assert consistency.ei_shift_px(moved, reconstructor.views._ei) == pytest.approx((dx, dy), abs=0.1)
    with pytest.raises(SsdpcError, match=re.escape(f"sit {dx:+.1f}, {dy:+.1f} px (x, y) from where the calibration")):
        reconstructor.reconstruct(moved)
    edited = dataclasses.replace(calibration, centres_px=calibration.centres_px - np.array([dx, dy]))
    with pytest.raises(SsdpcError, match="flat frame: its elemental images sit"):
        Reconstructor(run_config(case.optics, z=(-30, 30), dz=2), edited, flat=case.flat)


@pytest.mark.parametrize("shift", [(2, 0), (-2, 3)])
def test_in_a_series_every_frame_is_checked_for_a_moved_camera(case, calibration, monkeypatch, shift):
    """The frames between the full checks (every tenth) are measured on the four brightest
    elemental images (as precise as all of them where 16 are lit: docs/performance.md): a camera
    moved in the middle of a series is refused on the first moved frame."""
    from napari_ssdpc.reconstruction import consistency, contrast

    monkeypatch.setattr(contrast, "EI_CHECK_S", 1e9)  # the frame count alone (a fast series)
    views = Reconstructor(run_config(case.optics, z=(-30, 30), dz=2), calibration, flat=case.flat).views
    dx, dy = shift
    moved = np.roll(case.frame, (dy, dx), axis=(0, 1))
    assert len(views._ei_few[1]) == min(contrast.EI_FEW, len(views._ei[1]))
    assert consistency.ei_shift_px(moved, views._ei_few) == pytest.approx((dx, dy), abs=0.1)
    for _ in range(3):
        views.measure(case.frame)  # frame 0 on every EI, frames 1 and 2 on four
    with pytest.raises(SsdpcError, match=re.escape(f"sit {dx:+.1f}, {dy:+.1f} px (x, y)")):
        views.measure(moved)  # frame 3, on four


def test_the_objects_of_the_reconstructed_weak_bead(result):
    """End to end: the bead measured on its `tv` reconstruction (condenser NA 0.1, dz 2 µm)."""
    from napari_ssdpc.analysis.objects import measure_objects

    objects = measure_objects(result.delta_n, result.z_um, result.y_um, result.x_um, n_medium=1.518)
    assert len(objects) == 1
    (o,) = objects
    truth = 0.01 * 4 / 3 * np.pi * 3.0**3  # ∫Δn dV of the 6 µm bead, µm³
    whole = float(result.delta_n.sum()) * float(np.prod(result.voxel_um))
    assert whole == pytest.approx(truth, rel=0.05)  # measured 0.99: the reconstruction holds the mass
    # the object holds 0.88 of it; the rest is a haze over the whole volume below 5% of the peak
    # (at condenser NA 0.3 the weak beads measure 0.97-0.98: docs/measurements.md)
    assert 0.85 * truth < o["integrated_dn_um3"] < whole
    assert o["dry_mass_pg"] == pytest.approx(o["integrated_dn_um3"] / 0.19)
    assert np.hypot(o["x_um"] - 4.0, o["y_um"] + 3.0) < 0.5 and abs(o["z_um"]) < 3.0  # measured 0.01, -2.1 µm
    assert o["peak_ri"] == pytest.approx(1.518 + float(result.delta_n.max()), abs=1e-6)  # the volume's peak


def test_the_methods_read_the_light_field_views_through_measurements(reconstructor):
    """The light-field front end keeps the Measurements protocol every method reads, and its two
    models keep the protocols the solvers take (ViewModel's TransferFunctions, NonlinearModel)."""
    from napari_ssdpc.reconstruction.measurements import Measurements
    from napari_ssdpc.reconstruction.nonlinear import NonlinearModel
    from napari_ssdpc.settings.reconstruction import MultisliceSettings

    views = reconstructor.views
    assert isinstance(views, Measurements)
    np.testing.assert_array_equal(views.direct_light, views.level[views.lit])
    model = views.linear_model([-2.0, 0.0, 2.0])
    assert model.n_views == len(views.lit) and model.pixel_um == views.pixel_um
    roi = (slice(10, 26), slice(10, 26))
    ms = views.multislice_model([-2.0, 0.0, 2.0], 2.0, roi, MultisliceSettings(refine=1, source_spacing_na=0.05))
    assert isinstance(ms, NonlinearModel) and ms.view_shape == (len(views.lit), 16, 16)
    np.testing.assert_allclose(ms.views(np.zeros(ms.shape, np.float32)), 1.0, atol=1e-4)


def test_the_refinement_reuses_the_tv_answer_of_the_same_frame(case, calibration):
    """'tv', then its multislice refinement on the same Reconstructor: no operator is rebuilt and
    'tv' is not solved again (napari and the demo refine the answer on screen); another frame, or
    a plain 'tv' run, solves anew; going back to 'tv' takes the same built method."""
    more = {"iterations": 2, "stop_residual_over_noise": 0.0, "sphere_start": False}
    rec = Reconstructor(run_config(case.optics, z=(-30, 30), dz=2, multislice=more), calibration, flat=case.flat)
    tv_method = rec.method
    first = rec.reconstruct(case.frame)
    assert "tv_reused" not in first.settings and rec.reconstruct(case.frame).settings.get("tv_reused") is None
    config = run_config(case.optics, z=(-30, 30), dz=2, method="multislice", multislice=more)
    assert rec.adopt(config) and rec.method.name == "multislice" and rec.method.start is tv_method
    refined = rec.reconstruct(case.frame)
    assert refined.settings["tv_reused"] is True and refined.settings["multislice_iterations_run"] == 2
    assert refined.settings["tv_iterations_run"] == first.settings["tv_iterations_run"]
    other = rec.reconstruct(np.roll(case.frame, 1, axis=0))  # another frame: its own tv solve
    assert "tv_reused" not in other.settings
    assert rec.adopt(run_config(case.optics, z=(-30, 30), dz=2)) and rec.method is tv_method
    assert not rec.adopt(run_config(case.optics, z=(-30, 30), dz=2, method="wotf"))  # other operators


def test_the_bead_figure_is_readable_at_1280_px_and_the_solver_has_its_own(result, tmp_path):
    """summary.png of the demo: slices, profiles against the truth and the bead's numbers in 1280 x 800
    px (it was a 2052 x 351 strip); the solver's convergence in a figure of its own."""
    import matplotlib.image as mpimg

    from napari_ssdpc.validation.figures import bead_figure, solver_figure

    bead_figure(result, BEAD, BEAD.medium_index, tmp_path / "summary.png", "a weak bead")
    assert mpimg.imread(tmp_path / "summary.png").shape[:2] == (800, 1280)
    assert solver_figure(result, tmp_path / "solver.png") == tmp_path / "solver.png"
    assert mpimg.imread(tmp_path / "solver.png").shape[1] <= 1280
    no_iterations = type(result)(**{**result.__dict__, "convergence": {}})
    assert solver_figure(no_iterations, tmp_path / "none.png") is None and not (tmp_path / "none.png").exists()
