"""A stand-in for a GPU backend that runs anywhere: NumPy underneath, CuPy's rules on top.

Arrays made through its ``xp`` are :class:`DeviceArray` objects that, like CuPy arrays, refuse to
mix with host (NumPy) arrays: a NumPy function called on one, an implicit conversion to NumPy, or
a host array in an operation with one is a ``TypeError``. Code that passes with this backend
therefore keeps its arrays on the backend's device and moves them only through ``bk.asarray``
and ``bk.to_host``, which is what a CuPy run needs; the numbers are NumPy's, so they can be
compared with the CPU backend exactly. Imported by the tests as ``fake_device``.
"""

from __future__ import annotations

import types

import numpy as np
import scipy.fft
from numpy.lib.mixins import NDArrayOperatorsMixin

from napari_ssdpc.backend import Backend

__all__ = ["DeviceArray", "fake_gpu"]


class DeviceArray(NDArrayOperatorsMixin):
    """An array "on the device": NumPy inside, reachable only through the fake ``xp``."""

    __slots__ = ("a",)

    def __init__(self, a):
        self.a = a

    def __array__(self, dtype=None, copy=None):
        raise TypeError("implicit conversion of a device array to NumPy; copy it with bk.to_host")

    def __array_function__(self, func, types_, args, kwargs):
        raise TypeError(f"numpy.{func.__name__} called on a device array; use bk.xp.{func.__name__}")

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        out = kwargs.get("out")
        if out is not None:
            kwargs["out"] = tuple(_unwrap(o) for o in out)
        res = getattr(ufunc, method)(*(_unwrap(x) for x in inputs), **kwargs)
        return (out[0] if len(out) == 1 else out) if out is not None else _wrap(res)

    def __getattr__(self, name):
        if name.startswith("__"):  # no __array_interface__ and the like: NumPy must not see inside
            raise AttributeError(name)
        value = getattr(self.a, name)
        return _on_device(value) if callable(value) else _wrap(value)

    def __getitem__(self, key):
        return _wrap(self.a[_unwrap(key)])

    def __setitem__(self, key, value):
        self.a[_unwrap(key)] = _unwrap(value)

    def __len__(self):
        return len(self.a)

    def __float__(self):
        return float(self.a)

    def __int__(self):
        return int(self.a)

    def __bool__(self):
        return bool(self.a)


def _unwrap(x):
    if isinstance(x, DeviceArray):
        return x.a
    if isinstance(x, np.ndarray):
        raise TypeError(f"a host array {x.shape} in a device operation; move it with bk.asarray")
    if isinstance(x, tuple | list):
        return type(x)(_unwrap(v) for v in x)
    if isinstance(x, dict):
        return {k: _unwrap(v) for k, v in x.items()}
    return x


def _wrap(x):
    if isinstance(x, np.ndarray | np.generic):
        return DeviceArray(np.asarray(x))
    if isinstance(x, tuple | list):
        return type(x)(_wrap(v) for v in x)
    return x


def _on_device(fn):
    def call(*args, **kwargs):
        return _wrap(fn(*_unwrap(args), **_unwrap(kwargs)))

    return call


class _Module:
    """A module whose functions take and return device arrays (types and constants pass through)."""

    def __init__(self, module):
        self._module = module

    def __getattr__(self, name):
        obj = getattr(self._module, name)
        if isinstance(obj, types.ModuleType):
            return _Module(obj)
        if isinstance(obj, type) or not callable(obj):
            return obj
        return _on_device(obj)


class _FakeCupy(_Module):
    """``numpy`` with CuPy's transfers: ``asarray`` takes host arrays, ``asnumpy`` gives them back."""

    cuda = types.SimpleNamespace(get_current_stream=lambda: types.SimpleNamespace(synchronize=lambda: None))

    def asarray(self, a, dtype=None):
        return DeviceArray(np.asarray(a.a if isinstance(a, DeviceArray) else a, dtype=dtype))

    def asnumpy(self, a):
        return np.array(a.a)


def fake_gpu() -> Backend:
    """A 'gpu' backend on NumPy with CuPy's separation of host and device arrays."""
    return Backend("gpu", _FakeCupy(np), _Module(scipy.fft), -1, "fake device (NumPy)")
