"""Every reconstruction setting can be set from the command line, by a flag generated from its model."""

import argparse

import pytest
from pydantic import BaseModel

from napari_ssdpc.cli.options import FLAGS, add_reconstruction_options, config_from_args
from napari_ssdpc.settings.reconstruction import ReconstructionSettings


def _parser():
    p = argparse.ArgumentParser()
    add_reconstruction_options(p)
    return p


def test_every_key_of_every_section_has_a_flag():
    reached = set(FLAGS.values()) | {"multislice.roi_um", "z_min_um", "z_max_um"}  # --roi, --z
    for section, info in ReconstructionSettings.model_fields.items():
        model = info.annotation
        if isinstance(model, type) and issubclass(model, BaseModel):
            for key in model.model_fields:
                assert f"{section}.{key}" in reached or ("*.alpha" in reached and key == "alpha"), (section, key)


@pytest.mark.parametrize(
    "argv, section, key, value",
    [
        (["--multislice-iterations", "7"], "multislice", "iterations", 7),
        (["--multislice-source-spacing-na", "0.05"], "multislice", "source_spacing_na", 0.05),
        (["--multislice-unknowns", "views"], "multislice", "unknowns", "views"),
        (["--wotf-alpha", "0.3"], "wotf", "alpha", 0.3),
        (["--tv-iterations", "12"], "tv", "iterations", 12),  # a short flag of the same shape stays
    ],
)
def test_a_generated_flag_sets_its_key(argv, section, key, value):
    rec = config_from_args(_parser().parse_args(argv), None).reconstruction
    assert getattr(getattr(rec, section), key) == value


def test_a_generated_flag_is_checked_by_its_model():
    from napari_ssdpc.errors import SsdpcError

    with pytest.raises(SsdpcError, match="iterations"):
        config_from_args(_parser().parse_args(["--multislice-iterations", "0"]), None)


def test_the_chosen_methods_alpha_is_resolved_in_one_place():
    """'--alpha' (the '*' section) lands in the section of the method chosen on the same line, also
    for multislice (its start is tv's), through the same merge napari and RunConfig.of use."""
    from napari_ssdpc.settings.reconstruction import merge_settings

    for method, section in (("wotf", "wotf"), ("rl", "rl"), ("multislice", "tv")):
        rec = config_from_args(_parser().parse_args(["--method", method, "--alpha", "0.7"]), None).reconstruction
        assert getattr(rec, section).alpha == 0.7 and rec.alpha == 0.7
    base = ReconstructionSettings().to_dict()
    merged = merge_settings(base, {"*": {"alpha": 0.2}, "method": "wotf", "tv": {"iterations": 9}})
    assert merged["wotf"]["alpha"] == 0.2 and merged["tv"]["alpha"] == base["tv"]["alpha"]
    assert merged["tv"] == {**base["tv"], "iterations": 9} and base["tv"]["iterations"] != 9  # a copy
