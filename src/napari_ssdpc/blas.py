"""Small batched matrix products on one BLAS thread (the solvers' per-frequency products).

The products of the solvers are many small matrices, one per band frequency (views x planes,
16-24 x 100-300). Beyond a size (about 16 x 270 complex64) OpenBLAS splits each one over its
threads, which costs far more than it gives on a busy machine: 6000 products of 24 x 285 took
9.3 s against 62 ms on one thread with another job beside them (docs/performance.md). While a
block runs under :data:`one_blas_thread`, BLAS (OpenBLAS, MKL; through threadpoolctl) runs on one
thread; FFTs keep every core. The hold is counted, so that nested and concurrent holders (a
series' worker threads) share one limit and the last one out restores the threads the process had.
"""

from __future__ import annotations

import functools
import threading
from typing import Any

import numpy as np

__all__ = ["matmul", "one_blas_thread"]


class _OneBlasThread:
    """While any holder is inside, BLAS runs on one thread (counted: see the module)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._holders = 0
        self._limiter: Any = None

    def __enter__(self):
        with self._lock:
            if self._holders == 0:
                self._limiter = _blas().limit(limits=1, user_api="blas")
            self._holders += 1
        return self

    def __exit__(self, *exc):
        with self._lock:
            self._holders -= 1
            if self._holders == 0:
                self._limiter.restore_original_limits()
                self._limiter = None


@functools.cache
def _blas():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


#: The process's hold on BLAS: ``with one_blas_thread: ...`` runs the block's matrix products and
#: inverses on one BLAS thread; the threads come back when the last holder leaves.
one_blas_thread = _OneBlasThread()


def matmul(a, b):
    """``a @ b``, batched over the leading axes; on the CPU with BLAS held to one thread.

    Parameters
    ----------
    a : ndarray (NumPy or CuPy), (..., M, N)
    b : ndarray (same module), (..., N, L)

    Returns
    -------
    ndarray, (..., M, L)
    """
    if isinstance(a, np.ndarray):
        with one_blas_thread:
            return a @ b
    return a @ b  # CuPy: cuBLAS
