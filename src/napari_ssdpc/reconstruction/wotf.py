"""3D phase from the lenslet views by a linear inversion of their weak-object transfer functions.

The views' contrast obeys the first-order model of :mod:`.forward` (paper Eqs. 2-4):
per lateral frequency u, ĉ(u) = A(u) φ̂(u) with A a K x Z matrix (K views, Z slabs). With a
handful of views this is under-determined along z; the Tikhonov solution (paper Eq. 7
generalised from 2 DPC images to K views and Z slices) is, per spatial frequency,

    φ̂(u) = Aᴴ (A Aᴴ + α I)⁻¹ ĉ(u)          (a K x K system)

The rows of A carry the noise weights w_k (dim views are noisier, :mod:`.forward`). The Z x K
matrix Aᴴ(AAᴴ + αI)⁻¹ is built once, so a frame costs K real FFTs, one batched matrix product on
the band (beyond |u| = 2ρ the solution is zero) and Z inverse FFTs. φ_z is the phase of a slab
of thickness dz, so Δn = λ φ_z / (2π dz) (docs/conventions.md).
"""

from __future__ import annotations

import numpy as np

from napari_ssdpc.blas import one_blas_thread
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.forward import ViewModel, apply


class WotfInversion:
    """The Tikhonov inverse of a :class:`~napari_ssdpc.reconstruction.forward.ViewModel`.

    Parameters
    ----------
    model : ViewModel
        The views' model on the output planes.
    alpha : float
        Regularisation, relative to the strongest frequency's Σ_k,z |A|² / K (> 0).
    """

    def __init__(self, model: ViewModel, alpha: float):
        if not alpha > 0:
            raise SsdpcError(f"alpha must be > 0, got {alpha}")
        self.model = model
        xp = model.bk.xp  # NumPy or CuPy: the model's device
        a = model.a
        a_h = xp.ascontiguousarray(xp.conj(a).transpose(0, 2, 1))  # (P, Z, K)
        k = model.n_views
        self.alpha = float(alpha)
        with one_blas_thread:  # many small products and inverses (see napari_ssdpc.blas)
            gram = a @ a_h  # (P, K, K)
            scale = float(xp.max(xp.real(xp.trace(gram, axis1=1, axis2=2)))) / k
            self.alpha_abs = self.alpha * scale
            inv = xp.linalg.inv(gram + self.alpha_abs * xp.eye(k, dtype=np.complex64))
            self.inverse = (a_h @ inv).astype(np.complex64)  # (P, Z, K)

    def phase(self, contrast) -> np.ndarray:
        """Phase per slab, (Z, ny, nx) float32 rad, from the views' contrast (K, ny, nx).

        Parameters
        ----------
        contrast : ndarray, float32, (K, ny, nx)

        Returns
        -------
        numpy.ndarray, float32, (Z, ny, nx)
            On the host, whatever the model's device.
        """
        spec = self.model.spectra(contrast)  # (P, K)
        return self.model.bk.to_host(self.model.images(apply(self.inverse, spec)))
