"""From a raw frame to the views' contrast: checked once, extracted once, flat-fielded.

Per frame (paper §2, docs/conventions.md): the frame is checked (shape, light, saturation, the
condenser NA its lenslets' light shows, its elemental images where the calibration puts them), the
dark offset is subtracted, every elemental image is resampled once onto the upright object grid
(:func:`~napari_ssdpc.calibration.views.extract_views`), the light of every lenslet is checked
against the flat, and each lit view is divided by its flat (its direct-light background becomes
1). Lenslets that receive no direct light at this condenser NA (dark field) carry no first-order
phase signal (docs/conventions.md) and are left out.
"""

from __future__ import annotations

import time

import numpy as np

from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.calibration.views import ViewSampler, view_grid
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.physics import transfer
from napari_ssdpc.physics.design import design
from napari_ssdpc.physics.views_multislice import ViewsMultislice
from napari_ssdpc.reconstruction import checks, consistency
from napari_ssdpc.reconstruction.forward import ViewModel
from napari_ssdpc.settings.lenslets import HALVES
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.statistics import robust_sigma

__all__ = ["EI_CHECK_FRAMES", "EI_CHECK_S", "EI_FEW", "LEVEL_STEP", "ViewContrast"]

#: A frame's light levels and exposure are medians over every LEVEL_STEP-th view pixel in y and x.
LEVEL_STEP = 3
#: Every frame's elemental images are checked for a shift (a moved camera or array): on every lit
#: one for the first frame, every EI_CHECK_FRAMES-th and any frame EI_CHECK_S after the last such
#: check; on the EI_FEW brightest (wholly lit: clean disks) for the frames between (a quarter of the cost).
EI_CHECK_FRAMES = 10
EI_CHECK_S = 2.0
EI_FEW = 4


def _noise(dark) -> float:
    """Robust standard deviation of the dark pixels (MAD x 1.4826), camera units."""
    return max(robust_sigma(dark), 1e-6) if dark.size else 1e-6


class ViewContrast:
    """The flat field and the lit lenslets of one calibration: built once, used for every frame.

    Parameters
    ----------
    optics : Optics
    calibration : Calibration
    flat : ndarray, (H, W), optional
        Flat frame (no sample, the raw frames' condenser NA), camera units; None: each view is
        normalised by its median and the lit lenslets come from the transfer model.
    dark : float, optional
        Dark offset, camera units; None: estimated on every frame.
    min_light : float
        A lenslet counts as lit when its direct light reaches this fraction of the brightest.

    Attributes
    ----------
    lit : ndarray of int, (K_lit,)
        Indices of the lit lenslets in ``calibration.lenslets``.
    lenslets : list of Lenslet
        The lit lenslets.
    level : ndarray, (K,)
        Every lenslet's direct light (the flat's median, or the model's I0_k).
    mask : ndarray of bool, (h, w)
        The field stop on the view grid.
    view_mask : ndarray of bool, (K_lit, h, w)
        Where each lit view holds data.
    halves : dict of str to list of int
        The members (indices into ``lenslets``) of the up, down, left and right halves.
    x_um, y_um : ndarray, (w,), (h,)
        The view grid, µm from the optical axis.
    pixel_um : float
        Object-space pixel, µm.
    """

    def __init__(self, optics: Optics, calibration: Calibration, flat=None, dark=None, min_light: float = 0.05):
        self.optics, self.calibration = optics, calibration
        if dark is not None and not (isinstance(dark, (int, float, np.number)) and 0 <= float(dark) < np.inf):
            raise SsdpcError(f"dark = {dark!r}: give the camera's dark offset in camera units (a number >= 0), or None")
        if not 0 < float(min_light) < 1:
            raise SsdpcError(f"min_light = {min_light!r}: give a fraction of the brightest lenslet's light, 0 to 1")
        self.dark = None if dark is None else float(dark)
        cal = calibration
        geom = view_grid(cal)  # the views' grid, from the calibration alone
        self.mask = geom.mask
        self._sample = ViewSampler.of(cal)  # every frame's views: indices and weights computed once
        self._inside = self._sample.inside()  # where a view lies on the sensor (the dark offset applies)
        sparse = np.zeros(self.mask.shape, bool)
        sparse[::LEVEL_STEP, ::LEVEL_STEP] = True
        self._sparse = sparse & self.mask  # a frame's medians are taken over these view pixels
        self._levels = self._sample.subset(self._sparse)
        self._dark_index = checks.dark_pixel_index(cal)
        self._ei_since, self._ei_checked_at = EI_CHECK_FRAMES, -np.inf  # the first frame is checked
        self.x_um, self.y_um, self.pixel_um = geom.x_um, geom.y_um, geom.pixel_um
        fv = None
        #: The condenser NA the flat's lenslets look lit at (None without a flat).
        self.condenser_na_seen: float | None = None
        #: Every lenslet's light on the flat, (K,), camera units (None without a flat).
        self.flat_levels: np.ndarray | None = None
        if flat is not None:  # without a flat, each lenslet's direct light comes from the transfer model
            levels, noise, fv = self._measure(flat, "flat frame")
            self.flat_levels = levels
            self.condenser_na_seen = checks.check_flat(levels, noise, optics, lenslets=cal.lenslets)
            fv = np.clip(fv, 0, None)
        self.level = level = self._direct_light(fv)
        lit = level >= min_light * level.max()
        if not lit.any():
            raise SsdpcError("no lenslet receives direct light; check the flat frame and the condenser NA")
        self.lit = np.flatnonzero(lit)
        self.lenslets = [cal.lenslets[i] for i in self.lit]
        if fv is not None:
            consistency.check_lit_lenslets(self.lenslets, optics)
        self._ei = consistency.ei_templates(cal, self.lit)  # where the calibration puts the lit images
        brightest = self.lit[np.argsort(-level[self.lit], kind="stable")[:EI_FEW]]  # wholly lit: clean disks
        self._ei_few = consistency.ei_templates(cal, np.sort(brightest))
        if flat is not None:
            consistency.check_ei_shift(consistency.ei_shift_px(flat, self._ei), "flat frame")
        if fv is not None:
            sub = fv[self.lit]
            good = sub > 0.3 * np.median(sub[:, self.mask], axis=1)[:, None, None]
            self.flat: np.ndarray | None = np.where(good, sub, np.inf).astype(np.float32)
            self.view_mask = good & self.mask
        else:
            self.flat = None
            self.view_mask = np.broadcast_to(self.mask, (len(self.lit),) + self.mask.shape)
        self.halves = {h: [i for i, ln in enumerate(self.lenslets) if h in ln.halves] for h in HALVES}
        for h, members in self.halves.items():
            if not members:
                raise SsdpcError(
                    f"no lit lenslet in the '{h}' half: the optical axis is not centred among the "
                    "lit lenslets; recalibrate on a white frame or change the condenser NA"
                )

    @property
    def direct_light(self) -> np.ndarray:
        """Each lit view's direct light (the flat's median, or the model's I0_k), (K_lit,)."""
        return self.level[self.lit]

    @property
    def axial_resolution_um(self) -> float:
        """How far apart two planes the views tell apart, µm (R_z of paper Eq. 13 with tanθ = √2·d/f_fl)."""
        return float(design(self.optics)["r_z_ffl_um"])

    def linear_model(self, z_um, *, backend=None, progress=None) -> ViewModel:
        """The first-order model of the lit views (paper Eqs. 2-4): each lenslet's sub-aperture.

        Parameters
        ----------
        z_um, backend, progress
            As :meth:`~napari_ssdpc.reconstruction.measurements.Measurements.linear_model`.

        Returns
        -------
        ViewModel
        """
        return ViewModel.for_lenslets(
            self.optics,
            self.lenslets,
            self.mask.shape,
            self.pixel_um,
            z_um,
            i0=self.direct_light,
            progress=progress,
            backend=backend,
        )

    def multislice_model(self, z_um, dz_um: float, roi, settings, *, backend=None, max_bytes=None) -> ViewsMultislice:
        """The multislice model of the lit views (their lenslets' sub-apertures, the condenser's source points).

        Parameters
        ----------
        z_um, dz_um, roi, settings, backend, max_bytes
            As :meth:`~napari_ssdpc.reconstruction.measurements.Measurements.multislice_model`.

        Returns
        -------
        ViewsMultislice
        """
        return ViewsMultislice(
            self.optics,
            self.lenslets,
            self.x_um,
            self.y_um,
            z_um,
            roi=roi,
            refine=settings.refine,
            substeps=settings.substeps,
            source_subsamples=settings.source_subsamples,
            dz_um=dz_um,
            source_spacing_na=settings.source_spacing_na,
            max_bytes=max_bytes,
            backend=backend,
        )

    def _direct_light(self, flat_views):
        """Each lenslet's direct-light level: measured on the flat, else the model's I0_k."""
        if flat_views is not None:
            return np.array([np.median(v[self.mask]) for v in flat_views])
        shape = self.mask.shape
        _, _, i0 = transfer.lenslet_transfer_functions(self.optics, self.calibration.lenslets, shape, self.pixel_um)
        return np.asarray(i0, float)

    def _dark(self, frame, name: str):
        """Check a raw or flat frame; its dark offset and the noise of its dark pixels.

        Returns
        -------
        img : ndarray, float32, (H, W)
        dark : float
            Camera units.
        noise : float
            Noise of the dark pixels, camera units.
        """
        img = self.calibration.check_frame(frame, name=name)
        checks.check_constant(img, name)
        checks.check_saturated(frame, name)
        dark_px = img.ravel()[self._dark_index]
        if self.dark is None and dark_px.size < 100:
            raise SsdpcError(
                f"{name}: no dark pixels outside the elemental images to estimate the dark offset: the calibration's "
                "EI radius or centres do not fit this camera (recalibrate on a white frame), or give the dark "
                "offset (Python API: Reconstructor(..., dark=VALUE))"
            )
        dark = float(np.median(dark_px)) if self.dark is None else self.dark
        return img, dark, _noise(dark_px if dark_px.size else img.ravel())

    def lenslet_levels(self, frame, name: str = "flat frame"):
        """Every lenslet's light on a frame, without the checks of its condenser NA (for fitting it).

        Parameters
        ----------
        frame : ndarray, (H, W)
            Raw frame, camera units.
        name : str
            For the messages.

        Returns
        -------
        levels : ndarray, (K,)
            Every calibrated lenslet's median light above the dark level, camera units.
        noise : float
            Noise of the dark pixels, camera units.
        """
        levels, noise, _ = self._measure(frame, name)
        return levels, noise

    def _measure(self, frame, name: str):
        """Check the flat frame and extract all its views (every pixel of every lenslet counts).

        Returns
        -------
        levels : ndarray, (K,)
            Every lenslet's median light above the dark level.
        noise : float
            Noise of the dark pixels.
        views : ndarray, float32, (K, h, w)
            Dark-subtracted views of every lenslet.
        """
        img, dark, noise = self._dark(frame, name)
        views = self._sample(img) - np.float32(dark) * self._inside  # = the views of img − dark (extract_views)
        levels = np.array([np.median(v[self.mask]) for v in views])
        return levels, noise, views

    def _measure_frame(self, frame, name: str):
        """Check a raw frame: as :meth:`_measure`, but only the lit lenslets' views (K_lit, h, w), and
        the levels as medians over every :data:`LEVEL_STEP`-th view pixel in y and x (a few thousand
        pixels a lenslet: the light of a lenslet to 0.1 %, at a ninth of the cost)."""
        img, dark, noise = self._dark(frame, name)
        light = self._levels(img) - np.float32(dark) * self._inside[:, self._sparse]
        views = self._sample(img, self.lit) - np.float32(dark) * self._inside[self.lit]
        return np.median(light, axis=1), noise, views

    def _ei_check_due(self) -> bool:
        """Whether this frame's shift is measured on every lit elemental image (else on the
        :data:`EI_FEW` brightest): the first frame, then every
        :data:`EI_CHECK_FRAMES`-th and any frame :data:`EI_CHECK_S` after the last full check (a frame
        reconstructed on its own has all of them)."""
        now = time.monotonic()
        due = self._ei_since >= EI_CHECK_FRAMES - 1 or now - self._ei_checked_at >= EI_CHECK_S
        self._ei_since = 0 if due else self._ei_since + 1
        if due:
            self._ei_checked_at = now
        return due

    def __call__(self, frame, name: str = "frame") -> np.ndarray:
        """The views of a raw frame: :meth:`measure` without the exposure."""
        return self.measure(frame, name)[0]

    def measure(self, frame, name: str = "frame") -> tuple[np.ndarray, float]:
        """The views (see :meth:`__call__`) and the frame's exposure relative to the flat.

        A frame recorded with another exposure time, lamp power or gain than its flat has every
        view scaled by the same factor, and the first-order contrast I/I_flat − 1 with it (paper
        Eq. 3: the phase would scale too). The factor is the median over the lit views of each
        view's median (the background, where the sample does not cover most of the field); the
        views are divided by it, and a factor beyond ±10 % is reported.

        Parameters
        ----------
        frame : array_like, (H, W)
            Raw frame, camera units.
        name : str
            For the messages.

        Returns
        -------
        views : ndarray, float32, (K_lit, h, w)
            Dark-subtracted, flat-fielded, non-negative views of the lit lenslets: 1 where a view
            holds only direct light.
        exposure : float
            The frame's light over the flat's (1 without a flat).

        Raises
        ------
        SsdpcError
            The frame does not fit the calibration, holds no light, is saturated, is lit unlike
            the flat (a white frame, another condenser NA), its elemental images moved, or it is
            the flat itself.
        """
        levels, noise, views = self._measure_frame(frame, name)
        lit, expected = self.lit, self.level[self.lit]
        checks.check_frame_light(
            levels, noise, lit, expected, self.optics, name, self.calibration.lenslets, flat=self.flat is not None
        )
        templates = self._ei if self._ei_check_due() else self._ei_few  # every frame checked, most on a few EIs
        consistency.check_ei_shift(consistency.ei_shift_px(frame, templates), name)
        exposure = 1.0
        if self.flat is not None:
            views = views / self.flat
            sparse = self.view_mask & self._sparse
            exposure = float(np.median([np.median(v[m]) for v, m in zip(views, sparse)]))
            if np.all(np.abs(views[self.view_mask] - 1) < 1e-6):
                raise SsdpcError(
                    f"{name} equals the flat frame (no contrast at all): give the flat recorded without the sample"
                )
            consistency.check_exposure(exposure, name)
            views = views / exposure
        else:
            views = views / np.median(views[:, self._sparse], axis=1)[:, None, None]
        return np.clip(np.where(self.view_mask, views, 0), 0, None).astype(np.float32), exposure
