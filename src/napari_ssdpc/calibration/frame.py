"""A raw frame as the calibration and the reconstruction read it: a finite 2D grey-level image."""

from __future__ import annotations

import numpy as np

from napari_ssdpc.errors import SsdpcError

__all__ = ["validated"]


def validated(frame, name="frame") -> np.ndarray:
    """The frame as a float32 (H, W) array; one-line SsdpcError for anything else.

    Parameters
    ----------
    frame : array_like
    name : str
        How messages name it.

    Returns
    -------
    ndarray, float32, (H, W)
    """
    a = np.asarray(frame)
    if a.dtype.kind not in "uif":
        raise SsdpcError(
            f"{name}: dtype {a.dtype} is not a grey-level image; give the raw camera frame (integer or float)"
        )
    if a.ndim != 2:
        hint = "; pass one frame, e.g. frames[0]" if a.ndim == 3 else ""
        raise SsdpcError(f"{name}: expected a 2D frame (y, x), got shape {a.shape}{hint}")
    if min(a.shape) < 16:
        raise SsdpcError(f"{name}: shape {a.shape} is too small for a light-field frame; give the full camera frame")
    img = a.astype(np.float32, copy=False)
    if a.dtype.kind == "f" and not np.all(np.isfinite(img)):  # an integer frame is finite
        bad = int(img.size - np.count_nonzero(np.isfinite(img)))
        raise SsdpcError(f"{name}: {bad} NaN/inf pixels; replace them or re-export the frame")
    return img
