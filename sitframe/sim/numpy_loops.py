"""numpy's own float64 loops and OpenBLAS's ``ddot``, callable from a compiled kernel.

A log must not change when the learning loop is compiled, so a kernel has to compute every
logarithm, exponential, power and dot product exactly as numpy does. numba's own ``np.log``,
``np.exp`` and ``**`` call the C library, whose last bit differs from the vector library
numpy uses on a modern CPU (in 199 and 5173 of 100,000 logarithms and powers on an AVX-512
machine: ``benchmarks/sim/numpy_bits.py``). So a kernel calls numpy's own code:

* ``np.log``, ``np.exp``, ``np.power``: the contiguous float64 loop numpy itself runs, handed
  out by ``ufunc._resolve_dtypes_and_context`` and ``ufunc._get_strided_loop`` (numpy's
  experimental API of NEP 43, made for numba), called through a ``ctypes`` pointer with its
  context (:func:`ufunc_loop`);
* ``a @ b`` of two float64 vectors: ``cblas_ddot`` of the OpenBLAS numpy ships
  (:func:`openblas_ddot`).

:func:`loops` bundles them, or says why there are none (a numpy without the API or without
its own OpenBLAS). A caller still compares results with numpy's before relying on them
(``sitframe.runs.fused``): the pointers are numpy's own, but how numpy chooses a loop for a
given call (a scalar exponent, an unaligned array) is numpy's business.

It imports nothing of sitframe (the foot of the house).
"""

from __future__ import annotations

import ctypes
import glob
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Loops", "loops", "openblas_ddot", "ufunc_loop"]

_F8 = np.dtype(np.float64)
_CAPSULE = b"numpy_1.24_ufunc_call_info"
_get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
_get_pointer.restype = ctypes.c_void_p
_get_pointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
#: numpy's strided loop: ``int loop(context, char **data, npy_intp *dims, npy_intp *strides,
#: auxdata)``.
LOOP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                        ctypes.c_void_p, ctypes.c_void_p)
_KEEP: list[object] = []  # (the capsules own the loops' context and auxiliary data)


def ufunc_loop(ufunc: np.ufunc) -> tuple[Any, int, int]:
    """numpy's own contiguous float64 loop of ``ufunc``: ``(function, context, auxdata)``.

    Raises ``AttributeError`` or ``TypeError`` on a numpy without NEP 43's experimental API.
    """
    n = ufunc.nin + ufunc.nout
    _dtypes, cap = ufunc._resolve_dtypes_and_context((_F8,) * n)  # type: ignore[attr-defined]
    ufunc._get_strided_loop(cap, fixed_strides=(8,) * n)  # type: ignore[attr-defined]
    loop, context, aux = (ctypes.c_void_p * 3).from_address(_get_pointer(cap, _CAPSULE))
    _KEEP.append(cap)
    return LOOP(loop), int(context), int(aux or 0)


def openblas_ddot() -> Any | None:
    """``cblas_ddot`` of the OpenBLAS numpy ships (``numpy.libs``), or None where there is none."""
    where = os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs")
    for path in sorted(glob.glob(os.path.join(where, "libscipy_openblas*"))):
        lib = ctypes.CDLL(path)
        for name in ("scipy_cblas_ddot64_", "scipy_cblas_ddot", "cblas_ddot"):
            if hasattr(lib, name):
                f = getattr(lib, name)
                f.restype = ctypes.c_double
                f.argtypes = [ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64,
                              ctypes.c_void_p, ctypes.c_int64]
                return f
    return None


@dataclass(frozen=True)
class Loops:
    """The functions a kernel calls (each loop with its context and auxiliary data)."""

    log: tuple[Any, int, int]
    exp: tuple[Any, int, int]
    power: tuple[Any, int, int]
    ddot: Any


_CACHE: list[Loops | str] = []


def loops() -> Loops | str:
    """numpy's loops and OpenBLAS's ``ddot`` (once per process), or why they cannot be had."""
    if not _CACHE:
        try:
            found = (ufunc_loop(np.log), ufunc_loop(np.exp), ufunc_loop(np.power))
        except (AttributeError, TypeError, ValueError) as exc:
            _CACHE.append(f"numpy {np.__version__} hands out no strided loops ({exc})")
            return _CACHE[0]
        ddot = openblas_ddot()
        _CACHE.append("numpy ships no OpenBLAS of its own" if ddot is None
                      else Loops(*found, ddot))
    return _CACHE[0]
