"""What every phase method reads of a front end: the :class:`Measurements` protocol.

A front end turns an instrument's raw data into views: flat-fielded images of the sample, each
taken through its own part of the pupil or under its own illumination, whose direct light is 1.
The light-field views of this microscope
(:class:`~napari_ssdpc.reconstruction.contrast.ViewContrast`: one view per lit lenslet) are one
front end; another (an LED array's half-disk patterns, a fitted pupil) keeps the same protocol
and every method runs on it unchanged. The methods never see lenslets, a calibration or a flat:
only the views' grid and masks, their direct light, and the two models of the views that the
front end builds for its own optics, the first-order one (paper Eqs. 2-4) and the multislice one.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from napari_ssdpc.backend import Backend

__all__ = ["Measurements"]


@runtime_checkable
class Measurements(Protocol):
    """The views of a front end, as the phase methods read them.

    Attributes
    ----------
    mask : ndarray of bool, (ny, nx)
        The field stop on the views' grid: Δn = 0 outside.
    view_mask : ndarray of bool, (K, ny, nx)
        Where each view holds data.
    direct_light : ndarray, (K,)
        Each view's measured direct light (sets the views' weights), camera units or relative.
    pixel_um : float
        The views' object-side pixel, µm.
    x_um, y_um : ndarray, (nx,), (ny,)
        The views' grid (pixel centres), µm from the optical axis.
    """

    mask: np.ndarray
    view_mask: np.ndarray
    pixel_um: float
    x_um: np.ndarray
    y_um: np.ndarray

    @property
    def direct_light(self) -> np.ndarray:
        """Each view's measured direct light, (K,)."""
        ...

    @property
    def axial_resolution_um(self) -> float:
        """How far apart two planes the views tell apart, µm (what an iterative method pads its planes by)."""
        ...

    def linear_model(self, z_um, *, backend: str | Backend | None = None, progress=None) -> Any:
        """The first-order model of the views (a ``ViewModel``).

        Parameters
        ----------
        z_um : array_like, (Z,)
            Planes, µm.
        backend : {'cpu', 'gpu'} or Backend, optional
        progress : callable, optional
            ``progress(done, total, 'operators')`` while it is built.
        """
        ...

    def multislice_model(self, z_um, dz_um: float, roi, settings, *, backend=None, max_bytes=None) -> Any:
        """The multislice model of the views (a ``NonlinearModel``).

        Parameters
        ----------
        z_um : array_like, (Z,)
            Planes, µm (evenly spaced).
        dz_um : float
            Their spacing, µm.
        roi : (slice, slice)
            Rows and columns of the views' grid it covers (square).
        settings : MultisliceSettings
            Its sampling (refine, substeps, source points).
        backend : {'cpu', 'gpu'} or Backend, optional
        max_bytes : int, optional
            Refuse a model that needs more memory (:class:`~napari_ssdpc.errors.SsdpcError`).
        """
        ...
