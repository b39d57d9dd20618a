"""The second front end: images of a conventional DPC microscope (an LED array or a segmented
condenser lighting one half of the illumination disk per image), as the phase methods read them
(:class:`~napari_ssdpc.reconstruction.measurements.Measurements`).

Each image is one view: pattern p at focal plane f (view k = p·F + f, :mod:`~napari_ssdpc.physics.led_transfer`).
Its direct light is made 1 by dividing it by its running mean over half the field's shorter side
and then by its mean (the illumination of an LED array falls off across the field; the phase
contrast of a weak object averages out over such a window); its contrast I/I0 − 1 is then the first-order
model's (paper Eqs. 2-4) with the transfer functions of its own half-disk source and the whole pupil.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics.led_transfer import LedPatterns, led_source_points
from napari_ssdpc.physics.pupil import Pupil
from napari_ssdpc.physics.views_multislice import ViewsMultislice
from napari_ssdpc.reconstruction.forward import ViewModel
from napari_ssdpc.settings.dpc_optics import DpcOptics

__all__ = ["MULTISLICE_2D", "LedViews"]

#: Why a stack of one image a pattern has no multislice model (its one slab has no depth).
MULTISLICE_2D = "the 'multislice' method takes z-stacks (z_um in the optics file); use 'tv' for 2D"

#: Smallest image side the background window (half the shorter side) still leaves room for, px.
MIN_SIDE_PX = 32


class LedViews:
    """The views of a DPC stack: built once per optics and image size, then called per stack.

    Parameters
    ----------
    optics : DpcOptics
    shape : (int, int)
        (ny, nx) of one image, px.

    Attributes
    ----------
    mask : ndarray of bool, (ny, nx)
        The whole field.
    view_mask : ndarray of bool, (K, ny, nx)
        Every image holds data everywhere.
    pixel_um : float
        Object-side pixel, µm.
    x_um, y_um : ndarray
        Pixel centres, µm from the image centre.
    """

    def __init__(self, optics: DpcOptics, shape):
        self.optics = optics
        ny, nx = (int(n) for n in shape)
        if min(ny, nx) < MIN_SIDE_PX:
            raise SsdpcError(f"images of {ny} x {nx} px are too small for DPC; give at least {MIN_SIDE_PX} px a side")
        self.shape = (ny, nx)
        self.pixel_um = float(optics.pixel_um)
        self.x_um = (np.arange(nx) - (nx - 1) / 2) * self.pixel_um
        self.y_um = (np.arange(ny) - (ny - 1) / 2) * self.pixel_um
        self.mask = np.ones(self.shape, bool)
        self.n_views = len(optics.patterns_deg) * len(optics.focal_planes_um)
        self.view_mask = np.ones((self.n_views, ny, nx), bool)
        self._patterns: LedPatterns | None = None

    @property
    def patterns(self) -> LedPatterns:
        """The views' transfer functions (built on first use)."""
        if self._patterns is None:
            self._patterns = LedPatterns(self.optics, self.shape)
        return self._patterns

    @property
    def direct_light(self) -> np.ndarray:
        """Each view's direct light in the model, (K,): the images are normalised one by one."""
        return self.patterns.i0

    @property
    def axial_resolution_um(self) -> float:
        """How far apart two planes the views tell apart, µm (the images' depth of field)."""
        return float(self.optics.depth_of_field_um)

    def linear_model(self, z_um, *, backend=None, progress=None) -> ViewModel:
        """The first-order model of the views on the planes ``z_um``.

        Parameters
        ----------
        z_um, backend, progress
            As :meth:`~napari_ssdpc.reconstruction.measurements.Measurements.linear_model`.

        Returns
        -------
        ViewModel
        """
        return ViewModel(self.patterns, self.shape, self.pixel_um, z_um, progress=progress, backend=backend)

    def multislice_model(self, z_um, dz_um: float, roi, settings, *, backend=None, max_bytes=None) -> ViewsMultislice:
        """The multislice model of the views: every pattern's half of the illumination disk through
        the volume, the whole objective pupil, each image at its focal plane.

        Parameters
        ----------
        z_um, dz_um, roi, settings, backend, max_bytes
            As :meth:`~napari_ssdpc.reconstruction.measurements.Measurements.multislice_model`.

        Returns
        -------
        ViewsMultislice
        """
        o = self.optics
        if not o.is_stack:
            raise SsdpcError(MULTISLICE_2D)
        h = settings.source_spacing_na / o.wavelength_um
        return ViewsMultislice(
            o,
            np.zeros((self.n_views, 2)),  # every view: the whole pupil, centred on the axis
            self.x_um,
            self.y_um,
            z_um,
            roi=roi,
            refine=settings.refine,
            substeps=settings.substeps,
            dz_um=dz_um,
            max_bytes=max_bytes,
            backend=backend,
            pupil=Pupil(o.cutoff, o.cutoff),
            source=led_source_points(o, h, settings.source_subsamples),
            focus_um=np.tile(o.focal_planes_um, len(o.patterns_deg)),
        )

    def check(self, stack) -> np.ndarray:
        """The stack as (K, ny, nx) float64 images, refused in one line where it does not fit the optics.

        Parameters
        ----------
        stack : array_like, (P, ny, nx) or (P, F, ny, nx)
            As :meth:`__call__`.

        Returns
        -------
        ndarray, float64, (K, ny, nx)

        Raises
        ------
        SsdpcError
            A stack of the wrong shape, non-finite or dark images.
        """
        a = np.asarray(stack)
        n_p, n_f = len(self.optics.patterns_deg), len(self.optics.focal_planes_um)
        want = (n_p, *self.shape) if not self.optics.is_stack else (n_p, n_f, *self.shape)
        if a.shape != want and not (a.ndim == 3 and self.optics.is_stack and a.shape == (n_p * n_f, *self.shape)):
            kind = f"{n_p} patterns x {n_f} focal planes" if self.optics.is_stack else f"{n_p} patterns"
            raise SsdpcError(
                f"the stack is {a.shape}, the optics describe {kind} of {self.shape[0]} x {self.shape[1]} px "
                f"{want}; check patterns_deg{' and z_um' if self.optics.is_stack else ''} against the stack"
            )
        if not np.issubdtype(a.dtype, np.number) or np.issubdtype(a.dtype, np.complexfloating):
            raise SsdpcError(f"the stack holds {a.dtype} values; give camera intensities")
        a = a.reshape(self.n_views, *self.shape).astype(np.float64)
        if not np.isfinite(a).all():
            raise SsdpcError("the stack holds non-finite values (NaN or inf); give the camera's images")
        means = a.mean(axis=(-2, -1))
        if np.any(means <= 0) or np.any(a.min(axis=(-2, -1)) < -0.5 * means):
            k = int(np.argmin(means))
            raise SsdpcError(f"image {k} of the stack is dark (mean {means[k]:.3g}); check the exposure and the order")
        return a

    def __call__(self, stack) -> np.ndarray:
        """The stack's images as views whose direct light is 1.

        Parameters
        ----------
        stack : array_like, (P, ny, nx) or (P, F, ny, nx)
            One image per pattern in the order of ``patterns_deg`` (each a z-stack in the order
            of ``z_um``), camera units.

        Returns
        -------
        ndarray, float32, (K, ny, nx)

        Raises
        ------
        SsdpcError
            As :meth:`check`.
        """
        a = self.check(stack)
        means = a.mean(axis=(-2, -1))
        size = min(self.shape) // 2
        out = np.empty(a.shape, np.float32)
        for k, im in enumerate(a):
            level = im / np.maximum(ndimage.uniform_filter(im, size=size, mode="reflect"), 1e-12 * means[k])
            out[k] = level / level.mean()
        return out
