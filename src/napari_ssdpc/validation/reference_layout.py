"""Where the reference path puts the elemental images on its canvas, and its full-frame PSFs.

Layout. The fast path treats each view on its own (no light of one lenslet in another EI,
``physics/psf.py``). To compute that same model on a sensor, the EIs are laid out on the lenslet
lattice with a pitch of one convolution window (P, Q) px instead of the physical 145 px, so that
the blur and parallax margins of neighbouring EIs never overlap. ``canvas='sensor'`` keeps the
camera's frame size (as large as the toolboxes' FFTs; larger only when the spread lattice does
not fit), ``canvas='eis'`` only the box that holds the spread EIs (the cheapest honest
reference; docs/performance.md reports both).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from napari_ssdpc.backend import cpu
from napari_ssdpc.errors import SsdpcError

__all__ = ["CANVASES", "Layout", "full_frame_psf", "layout", "lenslet_kernels"]

CANVASES = ("sensor", "eis")


@dataclass(frozen=True)
class Layout:
    """Where the spread EIs lie on the canvas.

    The object grid (P, Q) of the fast path is circular; here it is linear, with object row i
    at position i (i < split) or i − P (i ≥ split), and placed on the canvas at rows [0, P)
    (position p at canvas row p + offset). Lenslet k's kernel sits at ``origins[k]``, so its
    view pixel j lies on canvas row ``origins[k] + offset + j``.

    Attributes
    ----------
    shape : tuple of int
        The canvas (rows, cols), px.
    fft_shape : tuple of int
        (P, Q): the fast path's padded view grid, px.
    view_shape : tuple of int
        (ny, nx) of a view, px.
    reach : tuple of int
        Kernel half-width kept (R_y, R_x) = ((P − ny)//2, (Q − nx)//2), px.
    origins : ndarray, int, (K, 2)
        Kernel centre (row, col) of each lenslet on the canvas, px.
    """

    shape: tuple  # canvas (rows, cols)
    fft_shape: tuple  # (P, Q): the fast path's padded view grid
    view_shape: tuple  # (ny, nx)
    reach: tuple  # kernel half-width kept (R_y, R_x): (P − ny)//2, (Q − nx)//2
    origins: np.ndarray  # (K, 2) kernel centre of each lenslet (row, col) on the canvas

    @property
    def split(self) -> tuple:
        """(rows, cols) where the fast path's circular grid wraps: view plus half the padding."""
        return tuple(n + (p - n) // 2 for n, p in zip(self.view_shape, self.fft_shape))

    @property
    def offset(self) -> tuple:
        """(rows, cols) the circular grid is rolled by to make it linear."""
        return tuple(p - s for p, s in zip(self.fft_shape, self.split))

    @property
    def area_ratio(self) -> float:
        """Canvas pixels per view-grid pixel of the fast path."""
        return self.shape[0] * self.shape[1] / (self.fft_shape[0] * self.fft_shape[1])

    def to_linear(self, obj):
        """Circular object grid (..., P, Q) -> linear (rolled so that position p sits at p + offset).

        Parameters
        ----------
        obj : ndarray, (..., P, Q)

        Returns
        -------
        ndarray, (..., P, Q)
        """
        return np.roll(obj, self.offset, axis=(-2, -1))

    def to_circular(self, obj):
        """Inverse of :meth:`to_linear`.

        Parameters
        ----------
        obj : ndarray, (..., P, Q)

        Returns
        -------
        ndarray, (..., P, Q)
        """
        return np.roll(obj, tuple(-o for o in self.offset), axis=(-2, -1))

    def windows(self, k):
        """Canvas slices (rows, cols) of lenslet k's view.

        Parameters
        ----------
        k : int
            Lenslet index.

        Returns
        -------
        (slice, slice)
        """
        (r, c), (oy, ox), (ny, nx) = self.origins[k], self.offset, self.view_shape
        return slice(r + oy, r + oy + ny), slice(c + ox, c + ox + nx)


def layout(rec, canvas: str = "sensor") -> Layout:
    """The spread-EI layout of a fast-path ``Reconstructor`` (with Richardson–Lucy operators).

    Parameters
    ----------
    rec : Reconstructor
    canvas : {'sensor', 'eis'}
        'sensor': the camera's frame size (larger only when the spread EIs do not fit);
        'eis': the box that holds the spread EIs, at a fast FFT size.

    Returns
    -------
    Layout
    """
    if canvas not in CANVASES:
        raise SsdpcError(f"unknown canvas '{canvas}'; use one of {', '.join(CANVASES)}")
    if rec.stacks is None:
        raise SsdpcError(
            "the reference path needs the Richardson-Lucy operators; build the Reconstructor "
            "with stacks=True or method='rl'"
        )
    p, q = rec.stacks.fft_shape
    ny, nx = rec.mask.shape
    reach = ((p - ny) // 2, (q - nx) // 2)
    cells = np.array([(ln.row, ln.col) for ln in rec.lenslets])
    cells -= cells.min(axis=0)
    origins = cells * np.array([p, q]) + np.array(reach)
    need = tuple(int(n * s + 2 * r) for n, s, r in zip(cells.max(axis=0) + 1, (p, q), reach))
    if canvas == "sensor":
        shape = tuple(max(int(a), b) for a, b in zip(rec.calibration.frame_shape, need))
    else:
        shape = tuple(sfft.next_fast_len(n, real=True) for n in need)
    return Layout(shape, (p, q), (ny, nx), reach, origins)


def lenslet_kernels(rec, z, lay: Layout):
    """Lenslet kernels of plane z, centre in the middle: the fast path's OTFs (full spectrum)
    back in real space, cropped to the reach.

    Parameters
    ----------
    rec : Reconstructor
        Built with the Richardson-Lucy operators.
    z : float
        The plane, µm.
    lay : Layout

    Returns
    -------
    ndarray, float, (K, 2 R_y + 1, 2 R_x + 1)
        Fraction of one lenslet's light per pixel.
    """
    ops = rec.stacks
    full = cpu().irfft2(ops.psf.otf(float(z), ops.fft_shape), s=ops.fft_shape)
    ry, rx = lay.reach
    full = np.roll(full, (ry, rx), axis=(-2, -1))
    return full[:, : 2 * ry + 1, : 2 * rx + 1]


def full_frame_psf(kernels, members, lay: Layout) -> np.ndarray:
    """The sensor image of an on-axis point through the lenslets ``members``: each kernel
    centred on its lenslet's origin (canvas-sized, float32).

    Parameters
    ----------
    kernels : ndarray, (K, kh, kw)
        The lenslets' kernels at one depth.
    members : sequence of int
        Lenslets of one half.
    lay : Layout

    Returns
    -------
    ndarray, float32, canvas shape
    """
    img = np.zeros(lay.shape, np.float32)
    ry, rx = lay.reach
    for k in members:
        r, c = lay.origins[k]
        img[r - ry : r + ry + 1, c - rx : c + rx + 1] += kernels[k]
    return img
