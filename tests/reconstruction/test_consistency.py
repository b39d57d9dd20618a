"""The condenser NA measured from a frame's lenslets: a sample that moves the lenslets' light is not
taken for another condenser NA, a frame at another NA is."""

import warnings

import numpy as np
import pytest
from scipy import ndimage

from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.reconstruction import consistency
from napari_ssdpc.reconstruction.contrast import ViewContrast


def _modulated(flat, amp, rng):
    """The flat times a smooth random modulation of ``amp`` (a sample's content across the field)."""
    field = ndimage.zoom(rng.standard_normal((64, 77)), (flat.shape[0] / 64, flat.shape[1] / 77), order=1)
    return np.clip(flat * (1 + amp * field), 0, 4095).astype(np.uint16)


@pytest.mark.parametrize("with_flat", [True, False])
def test_sample_content_is_not_taken_for_another_condenser_na(synthetic_series, with_flat):
    """Smooth modulations of 30 % move the fitted NA of frames at 0.1 far (up to ~0.146), but the
    optics' NA still fits them within a small fraction of a lenslet's light: none is refused, and
    none reported where no flat is given (a raw frame is then the only measure of the NA)."""
    optics, cal, flat, _, _ = synthetic_series
    views = ViewContrast(optics, cal, flat=flat if with_flat else None)
    rng = np.random.default_rng(5)
    seen = []
    for _ in range(6):
        frame = _modulated(flat, 0.3, rng)
        with warnings.catch_warnings():
            warnings.filterwarnings("error", "(?s).*condenser NA", SsdpcWarning)
            views.measure(frame)  # neither refused nor reported
        levels, _, _ = views._measure(frame, "frame")
        seen.append(consistency.apparent_condenser_na(levels, cal.lenslets, optics))
    assert max(abs(s.na - 0.1) for s in seen) > 0.01  # the sample did move the fit
    assert max(s.excess * s.misfit for s in seen) < consistency.NA_EXCESS_LIGHT / 10


@pytest.mark.parametrize("na", [0.2, 0.3])
def test_the_same_frames_read_at_another_condenser_na_are_refused(synthetic_series, na):
    """Frames at 0.1 with a sample (5 % modulation), reconstructed without a flat as 0.2 or 0.3:
    refused with the NA they show (also where the optics' lit lenslets are mostly dark)."""
    optics, cal, flat, _, _ = synthetic_series
    frame = _modulated(flat, 0.05, np.random.default_rng(5))
    views = ViewContrast(optics.replace(condenser_na=na), cal)  # no flat: the raw frame's NA alone
    with pytest.raises(SsdpcError, match=rf"condenser NA of about 0\.(08|09|10|11|12)\d, but the optics say {na}"):
        views.measure(frame)
