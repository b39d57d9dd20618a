"""The validation's frame cache: a cached case of another phantom or instrument under the same name is
simulated again, never read as this one's."""

import numpy as np

from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.validation import cases


class _Made:
    def __init__(self, value):
        self.frame = value


def test_a_cached_case_is_read_only_for_the_same_phantom_and_optics(tmp_path, monkeypatch):
    made = []

    def simulate(phantom, optics, **_):  # a stand-in: each frame says what it was made of
        made.append(phantom)
        return _Made(np.full((4, 4), phantom.diameter_um))

    monkeypatch.setattr(cases, "simulate", simulate)
    monkeypatch.setattr(cases, "flat_frame", lambda optics, **_: np.zeros((4, 4)))
    monkeypatch.setattr(cases, "white_frame", lambda optics, **_: np.zeros((4, 4)))
    optics = cases.paper_optics(0.25)
    small, large = ph.Sphere((0.0, 0.0, 0.0), 5.0, 1.55), ph.Sphere((0.0, 0.0, 0.0), 7.0, 1.55)

    assert cases.simulate_case("bead", small, optics, cache_dir=tmp_path).frame[0, 0] == 5.0
    assert cases.simulate_case("bead", small, optics, cache_dir=tmp_path).frame[0, 0] == 5.0
    assert len(made) == 1  # read from the cache
    assert cases.simulate_case("bead", large, optics, cache_dir=tmp_path).frame[0, 0] == 7.0
    aberrated = optics.replace(aberrations={"objective_zernike_waves": [0.0] * 10 + [0.2]})
    assert cases.simulate_case("bead", large, aberrated, cache_dir=tmp_path).frame[0, 0] == 7.0
    assert len(made) == 3  # another phantom, another instrument: simulated again
