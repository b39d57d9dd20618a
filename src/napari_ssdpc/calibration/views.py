"""Elemental images (EIs) in and out of a raw frame.

``extract_views`` resamples every EI onto an upright object-aligned grid (rotation and
flips undone) around its own measured centre; ``insert_views`` puts views back on the
sensor. Coordinates: x = column, y = row, pixel centres at integers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.lenslets import Lenslet


@dataclass(eq=False)
class Views:
    """Elemental images resampled on an upright object grid.

    ``data[k]`` (h, w) is the EI of ``lenslets[k]``; pixel (i, j) shows the in-focus
    object point (``x_um[j]``, ``y_um[i]``) µm, with (0, 0) on the EI centre. ``mask`` is
    the iris disk (True inside).
    """

    data: np.ndarray
    lenslets: list[Lenslet]
    centres_px: np.ndarray
    x_um: np.ndarray
    y_um: np.ndarray
    mask: np.ndarray
    pixel_um: float
    frame_shape: tuple[int, int] = (0, 0)

    @property
    def extent_um(self) -> tuple[float, float, float, float]:
        """matplotlib ``imshow`` extent (left, right, bottom, top) in µm."""
        h = 0.5 * self.pixel_um
        return (float(self.x_um[0] - h), float(self.x_um[-1] + h), float(self.y_um[-1] + h), float(self.y_um[0] - h))


def _view_geometry(calibration: Calibration, size):
    """Object-pixel grid of the views and the sensor step per view pixel."""
    cal = calibration
    step = cal.grid.pitch_px / cal.optics.pitch_px  # sensor px per object pixel (1 at nominal pitch)
    if size is None:
        half = int(math.floor(cal.ei_radius_px / step))
        h = w = 2 * half + 1
    else:
        h, w = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))  # type: ignore[arg-type]
        if h < 1 or w < 1:
            raise SsdpcError(f"view size must be positive, got {size}")
    px = cal.optics.object_pixel_um
    ii = np.arange(h) - (h - 1) / 2
    jj = np.arange(w) - (w - 1) / 2
    return ii, jj, step, px


@dataclass(frozen=True, eq=False)
class ViewGrid:
    """The upright object grid every view is resampled on (no frame needed).

    Attributes
    ----------
    x_um, y_um : ndarray, (w,), (h,)
        Pixel centres, µm from the EI centre (the optical axis in the object).
    mask : ndarray of bool, (h, w)
        The iris disk (the field stop), True inside.
    pixel_um : float
        Object-side pixel, µm.
    """

    x_um: np.ndarray
    y_um: np.ndarray
    mask: np.ndarray
    pixel_um: float


def view_grid(calibration: Calibration, size=None) -> ViewGrid:
    """The grid :func:`extract_views` resamples every EI on, from the calibration alone.

    Parameters
    ----------
    calibration : Calibration
    size : int, optional
        View size (h = w), px; default the EI diameter on the object grid.

    Returns
    -------
    ViewGrid
    """
    ii, jj, step, px = _view_geometry(calibration, size)
    J, I = np.meshgrid(jj, ii)
    mask = (J**2 + I**2) * step**2 <= calibration.ei_radius_px**2
    return ViewGrid(jj * px, ii * px, mask, px)


def _sensor_coordinates(cal: Calibration, size) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Sensor (x, y) of every view pixel of every lenslet: (K, h*w) each, and (h, w)."""
    ii, jj, step, _ = _view_geometry(cal, size)
    J, I = np.meshgrid(jj, ii)
    off = np.stack([J.ravel(), I.ravel()], 1) @ cal.grid.matrix.T * step  # (h*w, 2) sensor (x, y)
    c = np.asarray(cal.centres_px, float)
    return c[:, None, 0] + off[None, :, 0], c[:, None, 1] + off[None, :, 1], (len(ii), len(jj))


@dataclass(frozen=True, eq=False)
class ViewSampler:
    """Bilinear resampling of every EI onto the view grid (:func:`extract_views` with ``order=1``),
    its sensor indices and weights computed once per calibration: a frame's views are then four
    gathers and three multiply-adds, several times faster than interpolating anew each frame.

    Attributes
    ----------
    index : ndarray, int32, (4, K, h*w)
        Flat sensor index of the four neighbours of each view pixel.
    weight : ndarray, float32, (4, K, h*w)
        Their bilinear weights; all 0 where the view pixel lies outside the frame (it reads 0).
    shape : tuple of int
        (h, w) of a view, px ((n,) for a :meth:`subset`).
    """

    index: np.ndarray
    weight: np.ndarray
    shape: tuple[int, ...]

    @classmethod
    def of(cls, calibration: Calibration, size=None) -> ViewSampler:
        """The sampler of a calibration's views.

        Parameters
        ----------
        calibration : Calibration
        size : int, optional
            View size (h = w), px; default the EI diameter on the object grid.

        Returns
        -------
        ViewSampler
        """
        xs, ys, shape = _sensor_coordinates(calibration, size)
        H, W = (int(v) for v in calibration.frame_shape)
        inside = (xs >= 0) & (xs <= W - 1) & (ys >= 0) & (ys <= H - 1)  # as map_coordinates' mode 'constant'
        x0, y0 = np.clip(np.floor(xs), 0, W - 1), np.clip(np.floor(ys), 0, H - 1)
        fx, fy = np.where(inside, xs - x0, 0.0), np.where(inside, ys - y0, 0.0)
        x1, y1 = np.minimum(x0 + 1, W - 1), np.minimum(y0 + 1, H - 1)
        index = np.stack([y0 * W + x0, y0 * W + x1, y1 * W + x0, y1 * W + x1]).astype(np.int32)
        weight = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy]) * inside
        return cls(index, weight.astype(np.float32), shape)

    def __call__(self, img, rows=None) -> np.ndarray:
        """The views of a frame.

        Parameters
        ----------
        img : ndarray, (H, W)
            The frame (the calibration's shape).
        rows : array_like of int, optional
            Lenslets (rows of the calibration's table) to resample; default all.

        Returns
        -------
        ndarray, float32, (K, h, w)
        """
        index, weight = (self.index, self.weight) if rows is None else (self.index[:, rows], self.weight[:, rows])
        flat = np.asarray(img).ravel()
        out = flat[index[0]] * weight[0]
        for k in range(1, 4):
            out += flat[index[k]] * weight[k]
        return out.reshape(index.shape[1], *self.shape).astype(np.float32, copy=False)

    def subset(self, pixels) -> ViewSampler:
        """The same resampling at some view pixels only (e.g. a sparse sample for a median).

        Parameters
        ----------
        pixels : ndarray of bool, (h, w)
            The view pixels to keep.

        Returns
        -------
        ViewSampler
            Its views are (K, n) for the n pixels kept.
        """
        keep = np.flatnonzero(np.asarray(pixels, bool).ravel())
        return ViewSampler(self.index[:, :, keep], self.weight[:, :, keep], (len(keep),))

    def inside(self) -> np.ndarray:
        """Where each view pixel lies on the frame: (K, h, w) float32, 1 inside, 0 outside.

        Returns
        -------
        ndarray
        """
        return self.weight.sum(0).reshape(-1, *self.shape)


def extract_views(frame, calibration: Calibration, size=None, *, order: int = 1) -> Views:
    """Stack of EIs (K, h, w) float32, resampled upright on the object grid.

    View pixel (i, j) of lenslet k samples the sensor at
    ``centre_k + matrix @ (j − j0, i − i0) * step`` (``Grid.object_to_sensor``), so the
    rotation/flip of the camera is undone and an in-focus object point at (x, y) µm
    lands at view pixel (x, y) / object_pixel_um from the centre.

    Parameters
    ----------
    frame : array_like, (H, W)
        Raw frame, camera units.
    calibration : Calibration
    size : int, optional
        View size (h = w), px; default the EI diameter on the object grid.
    order : int
        Spline order of the resampling.

    Returns
    -------
    Views
    """
    cal = calibration
    img = cal.check_frame(frame)
    c = np.asarray(cal.centres_px, float)
    if order == 1:
        data = ViewSampler.of(cal, size)(img)
    else:
        xs, ys, shape = _sensor_coordinates(cal, size)
        data = ndimage.map_coordinates(
            img, [ys.ravel(), xs.ravel()], order=order, mode="constant", cval=0.0, prefilter=order > 1
        )
        data = data.reshape(len(c), *shape).astype(np.float32)
    grid = view_grid(cal, size)
    return Views(
        data=data,
        lenslets=list(cal.lenslets),
        centres_px=c.copy(),
        x_um=grid.x_um,
        y_um=grid.y_um,
        mask=grid.mask,
        pixel_um=grid.pixel_um,
        frame_shape=(int(cal.frame_shape[0]), int(cal.frame_shape[1])),
    )


def insert_views(views: Views, calibration: Calibration, *, order: int = 1, fill: float = 0.0) -> np.ndarray:
    """Inverse of :func:`extract_views`: paint each view back inside its iris disk on the
    sensor (float32 frame of the calibration's shape; ``fill`` elsewhere).

    Parameters
    ----------
    views : Views
    calibration : Calibration
    order : int
        Spline order of the resampling.
    fill : float
        Value outside the iris disks.

    Returns
    -------
    ndarray, float32, (H, W)
    """
    cal = calibration
    H, W = cal.frame_shape
    out = np.full((H, W), fill, np.float32)
    step = cal.grid.pitch_px / cal.optics.pitch_px
    Ainv = np.linalg.inv(cal.grid.matrix)
    h, w = views.data.shape[1:]
    r = cal.ei_radius_px
    for k, (cx, cy) in enumerate(views.centres_px):
        x0, x1 = max(int(math.floor(cx - r)), 0), min(int(math.ceil(cx + r)) + 1, W)
        y0, y1 = max(int(math.floor(cy - r)), 0), min(int(math.ceil(cy + r)) + 1, H)
        if x0 >= x1 or y0 >= y1:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1].astype(float)
        inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
        d = np.stack([xx[inside] - cx, yy[inside] - cy], 1) @ Ainv.T / step  # view pixel offsets (j, i)
        vals = ndimage.map_coordinates(
            views.data[k],
            [d[:, 1] + (h - 1) / 2, d[:, 0] + (w - 1) / 2],
            order=order,
            mode="constant",
            cval=fill,
            prefilter=order > 1,
        )
        sub = out[y0:y1, x0:x1]
        sub[inside] = vals
    return out
