"""Optics model and design calculator (paper Eqs. 8-14)."""

import math
import warnings

import numpy as np
import pytest
import yaml

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics.design import design
from napari_ssdpc.physics.geometry import nominal_lenslets
from napari_ssdpc.settings.lenslets import circle_overlap_fraction
from napari_ssdpc.settings.optics import PAPER_OPTICS, Optics


@pytest.fixture
def paper():
    return Optics.paper()


def test_shared_yaml_matches_builtin(paper, shared_optics_path):
    assert Optics.from_yaml(shared_optics_path).to_dict() | {"name": ""} == paper.to_dict() | {"name": ""}


@pytest.mark.parametrize(
    "key, expected",
    [
        ("fov_um", 122.5),
        ("r_xy_um", 3.90),
        ("dof_fwhm_um", 132.53),
        ("dof_full_um", 265.06),
        ("dof_pitch_um", 919.1),
        ("r_z_ffl_um", 20.6),
        ("r_z_printed_um", 4.2),
    ],
)
def test_design_reproduces_paper_within_half_percent(paper, key, expected):
    tol = 0.005 if key not in ("r_z_ffl_um", "r_z_printed_um") else 0.01  # the paper prints R_z to 2-3 digits
    assert design(paper)[key] == pytest.approx(expected, rel=tol)


def test_derived_quantities(paper):
    assert paper.m_ei == pytest.approx(4.08)
    assert paper.object_pixel_um == pytest.approx(0.8456, abs=1e-4)
    assert paper.subaperture_na == pytest.approx(0.4 / 6)
    assert paper.f_obj_um == pytest.approx(10000.0)
    assert paper.m_r == pytest.approx(0.375)
    assert paper.ei_radius_px == pytest.approx(250 / 3.45)


def test_lenslet_table_is_balanced_with_signs(paper):
    lens = nominal_lenslets(paper)
    assert len(lens) == 32  # 6 x 6 minus the four corners outside the pupil
    halves = {h: sum(h in ln.halves for ln in lens) for h in ("up", "down", "left", "right")}
    assert halves == {"up": 16, "down": 16, "left": 16, "right": 16}
    for ln in lens:
        # u_k = -a / (lambda f_obj m_r): a lenslet right of the axis sees light tilted toward -x
        assert np.sign(ln.u[0]) == -np.sign(ln.a_um[0]) and np.sign(ln.u[1]) == -np.sign(ln.a_um[1])
        assert math.hypot(*ln.u) * paper.wavelength_um == pytest.approx(math.hypot(*ln.a_um) / 3750.0)
    fr = sorted(ln.fraction for ln in lens)
    assert fr[0] == pytest.approx(0.59, abs=0.01) and fr[-1] == 1.0


def test_axis_offset_moves_lenslets(paper):
    lens = {(l.row, l.col): l for l in nominal_lenslets(paper, axis_offset_um=(100.0, -50.0))}
    assert lens[(0, 0)].a_um == pytest.approx((150.0, 300.0))


def test_circle_overlap_fraction_exact_cases():
    assert circle_overlap_fraction(0.0, 1.0, 2.0) == pytest.approx(1.0)
    assert circle_overlap_fraction(3.5, 1.0, 2.0) == pytest.approx(0.0)
    # equal circles at distance r: lens area = (2pi/3 - sqrt(3)/2) r^2
    assert circle_overlap_fraction(1.0, 1.0, 1.0) == pytest.approx((2 * math.pi / 3 - math.sqrt(3) / 2) / math.pi)
    # Monte Carlo check of a partial overlap
    rng = np.random.default_rng(0)
    p = rng.uniform(-1, 1, (400000, 2))
    p = p[np.hypot(*p.T) <= 1] + [1.7, 0]
    assert circle_overlap_fraction(1.7, 1.0, 2.0) == pytest.approx(np.mean(np.hypot(*p.T) <= 2.0), abs=3e-3)


def _with(path, mutate):
    d = yaml.safe_load(yaml.safe_dump(PAPER_OPTICS))
    mutate(d)
    path.write_text(yaml.safe_dump(d))
    return path


@pytest.mark.parametrize(
    "mutate, words",
    [
        (lambda d: d["mla"].pop("pitch_um"), "missing key 'mla.pitch_um'"),
        (lambda d: d["mla"].update(pitch_mm=d["mla"].pop("pitch_um") / 1000), "rename the key"),
        (lambda d: d.update(wavelength_um=520), "check the unit"),
        (lambda d: d["sensor"].update(pixel_um=-3.45), "must be positive"),
        (lambda d: d["mla"].update(grid="triangle"), "'mla.grid' must be 'square' or 'hex'"),
        (lambda d: d.update(condenser_na=0.4), "no phase contrast with a split detection pupil"),
        (lambda d: d.update(colour="red"), "unknown key 'colour'"),
        (lambda d: d.update(reconstruction={"dz_um": 0}), "'dz_um' must be positive"),
        (lambda d: d.update(flip_x="false"), "'flip_x' must be true or false, got 'false' (write it without quotes)"),
        (lambda d: d["sensor"].update(width_px=2448.9), "'sensor.width_px' must be a whole number"),
        (lambda d: d["objective"].update(magnificaton=20), "did you mean 'magnification'"),
        (lambda d: d.update(wavelength_um="0.52"), "write it without quotes"),
        (lambda d: d.update(medium_index=float("nan")), "finite"),
    ],
)
def test_bad_yaml_gives_one_line_error(tmp_path, mutate, words):
    path = _with(tmp_path / "o.yaml", mutate)
    with pytest.raises(SsdpcError) as e:
        Optics.from_yaml(path)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_missing_file_and_bad_syntax(tmp_path):
    with pytest.raises(SsdpcError, match="not found"):
        Optics.from_yaml(tmp_path / "nope.yaml")
    (tmp_path / "bad.yaml").write_text("wavelength_um: [0.5\n")
    with pytest.raises(SsdpcError, match="not valid YAML"):
        Optics.from_yaml(tmp_path / "bad.yaml")


def test_high_condenser_na_warns(paper):
    with pytest.warns(SsdpcWarning, match="phase contrast is weak"):
        paper.replace(condenser_na=0.35)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        paper.replace(condenser_na=0.3)  # sigma 0.75: no warning


def test_yaml_round_trip(tmp_path, paper):
    o = paper.replace(flip_x=True, iris_radius_um=1000.0)
    o.to_yaml(tmp_path / "o.yaml")
    assert Optics.from_yaml(tmp_path / "o.yaml") == o


def test_illumination_regimes_follow_condenser_na(paper):
    # sigma 0.25: the four central lenslets straddle the source edge, the rest see dark field
    d = design(paper)
    assert (d["lenslets_inside"], d["lenslets_straddling"], d["lenslets_outside"]) == (0, 4, 28)
    # 0.3 NA covers the rings at 0.094 and 0.211 NA (+0.067 sub-aperture radius) wholly,
    # cuts the rings at 0.283 and 0.340 NA and misses the outer ring at 0.389 NA
    d = design(paper.replace(condenser_na=0.3))
    assert (d["lenslets_inside"], d["lenslets_straddling"], d["lenslets_outside"]) == (12, 12, 8)


def test_duplicated_key_nesting_and_encoding_are_one_line_errors(tmp_path):
    text = tmp_path / "dup.yaml"
    text.write_text(yaml.safe_dump(PAPER_OPTICS) + "condenser_na: 0.3\n")
    for path, words in [
        (text, "key 'condenser_na' is given twice"),
        (_write(tmp_path / "deep.json", "[" * 100000 + "]" * 100000), "nested too deeply"),
        (_write(tmp_path / "latin.yaml", b"name: caf\xe9\n"), "not a text file in UTF-8"),
        (_write(tmp_path / "list.yaml", "- 1\n- 2\n"), "expected a mapping"),
    ]:
        with pytest.raises(SsdpcError) as e:
            Optics.from_yaml(path)
        assert words in str(e.value) and "\n" not in str(e.value)


def _write(path, content):
    (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    return path


def test_optics_is_hashable_and_copies_are_independent(paper):
    other = paper.replace(condenser_na=0.3)
    assert hash(paper) != hash(other) and paper.condenser_na == 0.1 and other.condenser_na == 0.3
    assert hash(paper) == hash(Optics.paper())
    assert other.replace(na=0.5).objective.na == 0.5 and other.na == 0.4


def test_run_config_round_trip_and_optics_file_with_reconstruction(tmp_path, paper):
    from napari_ssdpc.settings import ReconstructionSettings, RunConfig

    cfg = RunConfig(optics=paper.replace(medium_index=1.33), reconstruction=ReconstructionSettings(dz_um=0.5))
    cfg.to_yaml(tmp_path / "run.yaml")
    assert RunConfig.from_yaml(tmp_path / "run.yaml") == cfg
    d = paper.to_dict() | {"reconstruction": {"z_min_um": -40.0, "z_max_um": 40.0}}
    (tmp_path / "o.yaml").write_text(yaml.safe_dump(d))
    assert RunConfig.from_yaml(tmp_path / "o.yaml").reconstruction.z_min_um == -40.0
    assert Optics.from_yaml(tmp_path / "o.yaml") == paper
    assert Optics.from_yaml(tmp_path / "run.yaml") == cfg.optics


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"z_min_um": -1e6, "z_max_um": 1e6}, "outside -5000 to 5000"),
        ({"dz_um": 0.001}, "outside 0.05 to 100"),
        ({"z_min_um": -1000.0, "z_max_um": 1000.0, "dz_um": 0.5}, "4001 planes"),
        ({"z_min_um": 10.0, "z_max_um": -10.0}, "z range is empty"),
        ({"tikhonov_alpha": float("inf")}, "finite"),
        ({"rl_iterations": None}, "must be a whole number"),
        ({"method": "magic"}, "must be 'tv', 'wotf', 'rl' or 'multislice'"),
        ({"dn_max": 0.0}, "'tv.dn_max' must be positive"),
        ({"tv_lambda": -1.0}, "'tv.lambda_scale' must be positive"),
        ({"sign": "positive"}, "must be 'auto', 'denser', 'lighter' or 'any'"),
        ({"tv": {"iterations": 0}}, "'tv.iterations' must be positive"),
        ({"wotf": {"alpha": 0.0}}, "'wotf.alpha' must be positive"),
        ({"rl": {"model": "exact"}}, "'rl.model' must be 'lenslet' or 'paper'"),
        ({"tv": {"lambda": 1.0}}, "unknown key 'tv.lambda'"),
    ],
)
def test_reconstruction_settings_refuse_impossible_values(changes, words):
    from napari_ssdpc.settings import ReconstructionSettings

    with pytest.raises(SsdpcError) as e:
        ReconstructionSettings.from_dict(changes, source="run.yaml")
    assert words in str(e.value) and "\n" not in str(e.value)


def test_each_method_reads_its_own_section_and_older_flat_keys_are_read_into_them():
    from napari_ssdpc.settings import ReconstructionSettings

    rec = ReconstructionSettings.from_dict({"method": "wotf", "wotf": {"alpha": 0.5}, "tv": {"sign": "lighter"}})
    assert rec.alpha == 0.5 and rec.section is rec.wotf and rec.tv.sign == "lighter" and rec.rl.alpha == 0.01
    old = {"method": "rl", "tikhonov_alpha": 0.02, "rl_iterations": 7, "model": "paper", "tv_iterations": 30}
    rec = ReconstructionSettings.from_dict(old)
    assert (rec.rl.alpha, rec.rl.iterations, rec.rl.model, rec.tv.iterations) == (0.02, 7, "paper", 30)
    assert rec.tv.alpha == 0.1  # the other methods keep their own defaults
    assert ReconstructionSettings.from_dict(rec.to_dict()) == rec
    # runtime keys (read at every solve) do not change the operators' key
    assert rec.with_section("tv", sign="denser", iterations=5).operator_key() == rec.operator_key()
    assert rec.with_section("rl", model="lenslet").operator_key() != rec.operator_key()


def test_hex_array_lenslets_have_six_neighbours_at_one_pitch():
    from napari_ssdpc.physics.lattice import Grid

    optics = Optics.paper().replace(grid="hex")
    a = np.array([ln.a_um for ln in nominal_lenslets(optics)])
    d = np.hypot(*(a[:, None, :] - a[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    assert np.allclose(d.min(axis=1), optics.pitch_um)
    inner = np.hypot(*a.T) < optics.pupil_radius_mla_um - 1.5 * optics.pitch_um
    assert inner.any() and (np.isclose(d[inner], optics.pitch_um).sum(axis=1) == 6).all()
    grid = Grid.nominal(optics, rotation_deg=2.0)
    assert Grid.from_dict(grid.to_dict()) == grid and grid.lattice == "hex"
    ln = nominal_lenslets(optics)[5]
    centre = grid.lattice_px(ln.row, ln.col)  # the sensor position agrees with a_um (axis at the vertex)
    expect = (
        np.asarray(grid.axis_px) + grid.matrix @ np.asarray(ln.a_um) / optics.pixel_um * grid.pitch_px / optics.pitch_px
    )
    assert np.allclose(centre, expect)
