"""Benchmark: can a compiled kernel give numpy's own bits for the arithmetic of a trial step?

Question: The logs must stay bit-identical, so a compiled (numba) learning loop must
compute every logarithm, power, dot product and row norm exactly as numpy does. numba's
own ``np.log`` and ``**`` call the C library, whose last bit differs from numpy's vector
library; can a kernel instead call numpy's own float64 loops, OpenBLAS's ``ddot`` (numpy's
``@`` of two vectors) and einsum's row-norm order, and what does each cost inside a kernel?
Output: a table printed: operation, sizes tried, results that differ from numpy's (of all
tried), nanoseconds per call inside a compiled loop, and per numpy call from Python.

How each is reached from a kernel (``sitframe.sim.numpy_loops`` and the compiled trial's
``row_norms``, which this script checks):

log, power
    ``ufunc._resolve_dtypes_and_context`` and ``ufunc._get_strided_loop`` (numpy's
    experimental API, NEP 43, made for numba) hand out the strided loop numpy itself runs
    for float64, with its context; a kernel calls that C function through a ``ctypes``
    pointer.
``a @ b`` (two vectors)
    numpy calls ``cblas_ddot`` of the OpenBLAS it ships (``numpy.libs``); a kernel calls the
    same symbol.
``np.einsum("ij,ij->i", X, X)``
    numpy's einsum runs its sum-of-products loop compiled for the x86-64 baseline (two
    lanes, no fused multiply-add): per lane, blocks of eight elements summed from the last
    pair to the first, the tail in pairs (the missing lane 0), then ``0 + (lane0 + lane1)``.
    Written out in the kernel.

Run::

    python benchmarks/sim/numpy_bits.py [--tries 2000] [--calls 200000]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numba
import numpy as np

from sitframe.runs.fused_kernels import row_norms  # (the compiled trial's own)
from sitframe.sim.numpy_loops import openblas_ddot, ufunc_loop

LOG, LOG_CTX, LOG_AUX = ufunc_loop(np.log)
POW, POW_CTX, POW_AUX = ufunc_loop(np.power)
DDOT = openblas_ddot()


@numba.njit(cache=True)
def _call1(loop, ctx, aux, x, out):  # type: ignore[no-untyped-def]
    ptrs = np.empty(2, dtype=np.intp)
    ptrs[0], ptrs[1] = x.ctypes.data, out.ctypes.data
    dims = np.full(1, x.size, dtype=np.intp)
    strides = np.full(2, 8, dtype=np.intp)
    return loop(ctx, ptrs.ctypes.data, dims.ctypes.data, strides.ctypes.data, aux)


@numba.njit(cache=True)
def _call2(loop, ctx, aux, x, y, out):  # type: ignore[no-untyped-def]
    ptrs = np.empty(3, dtype=np.intp)
    ptrs[0], ptrs[1], ptrs[2] = x.ctypes.data, y.ctypes.data, out.ctypes.data
    dims = np.full(1, x.size, dtype=np.intp)
    strides = np.full(3, 8, dtype=np.intp)
    return loop(ctx, ptrs.ctypes.data, dims.ctypes.data, strides.ctypes.data, aux)


@numba.njit(cache=True)
def _own_log_pow(x, y):  # type: ignore[no-untyped-def]
    """numba's own ``np.log`` and ``**`` (the C library's), for comparison."""
    return np.log(x), x ** y


@numba.njit(cache=True)
def _log_many(loop, ctx, aux, x, out, calls):  # type: ignore[no-untyped-def]
    for _ in range(calls):
        _call1(loop, ctx, aux, x, out)


@numba.njit(cache=True)
def _pow_many(loop, ctx, aux, x, y, out, calls):  # type: ignore[no-untyped-def]
    for _ in range(calls):
        _call2(loop, ctx, aux, x, y, out)


@numba.njit(cache=True)
def _ddot_many(f, a, b, calls):  # type: ignore[no-untyped-def]
    s = 0.0
    for _ in range(calls):
        s += f(a.size, a.ctypes.data, 1, b.ctypes.data, 1)
    return s


@numba.njit(cache=True)
def _norms_many(X, out, calls):  # type: ignore[no-untyped-def]
    for _ in range(calls):
        row_norms(X, out)


def _differ(sizes: tuple[int, ...], tries: int,
            one: Callable[[int], tuple[object, object]]) -> tuple[int, int]:
    """How many of ``tries`` draws per size give ours != numpy's (``one(size)`` draws once
    and returns both), and how many were tried."""
    bad = sum(not np.array_equal(*one(n)) for n in sizes for _ in range(tries))
    return bad, tries * len(sizes)


def _ns(f: Callable[[], object], calls: int) -> float:
    t = time.perf_counter()
    f()
    return (time.perf_counter() - t) / calls * 1e9


def _python_ns(f: Callable[[], object], calls: int) -> float:
    t = time.perf_counter()
    for _ in range(calls):
        f()
    return (time.perf_counter() - t) / calls * 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tries", type=int, default=2000, help="random inputs per size")
    ap.add_argument("--calls", type=int, default=200_000, help="calls timed per operation")
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    sizes = (8, 40, 48)  # a sonar reading (8 or 40 ranges), the memberships of 48 rules

    def log_once(n: int) -> tuple[np.ndarray, np.ndarray]:
        x, out = rng.uniform(1e-3, 5.0, n), np.empty(n)
        _call1(LOG, LOG_CTX, LOG_AUX, x, out)
        return out, np.log(x)

    def pow_once(n: int) -> tuple[np.ndarray, np.ndarray]:
        x, y, out = rng.uniform(1e-6, 50.0, n), np.full(n, -1.0 / rng.uniform(0.1, 2)), \
            np.empty(n)
        _call2(POW, POW_CTX, POW_AUX, x, y, out)
        return out, np.power(x, y)

    rows = []
    x, out = rng.uniform(1e-3, 5.0, 40), np.empty(40)
    _log_many(LOG, LOG_CTX, LOG_AUX, x, out, 1)
    rows.append(("np.log", sizes, *_differ(sizes, a.tries, log_once),
                 _ns(lambda: _log_many(LOG, LOG_CTX, LOG_AUX, x, out, a.calls), a.calls),
                 _python_ns(lambda: np.log(x, out=out), a.calls)))
    x, y, out = rng.uniform(1e-6, 50.0, 48), np.full(48, -2.5), np.empty(48)
    _pow_many(POW, POW_CTX, POW_AUX, x, y, out, 1)
    rows.append(("np.power", sizes, *_differ(sizes, a.tries, pow_once),
                 _ns(lambda: _pow_many(POW, POW_CTX, POW_AUX, x, y, out, a.calls), a.calls),
                 _python_ns(lambda: np.power(x, y, out=out), a.calls)))
    if DDOT is not None:
        def ddot_once(n: int) -> tuple[float, float]:
            u, v = rng.normal(size=n), rng.normal(size=n)
            return DDOT(n, u.ctypes.data, 1, v.ctypes.data, 1), float(u @ v)

        u, v = rng.normal(size=48), rng.normal(size=48)
        _ddot_many(DDOT, u, v, 1)
        rows.append(("a @ b (vectors)", (7, 48, 300), *_differ((7, 48, 300), a.tries, ddot_once),
                     _ns(lambda: _ddot_many(DDOT, u, v, a.calls), a.calls),
                     _python_ns(lambda: u @ v, a.calls)))
    bad, total = 0, 0
    for d in (1, 3, 7, 8, 9, 16, 40):
        X = rng.normal(size=(a.tries, d)) * rng.uniform(1e-2, 1e2, (a.tries, 1))
        out = np.empty(a.tries)
        row_norms(X, out)
        bad += int((out != np.einsum("ij,ij->i", X, X)).sum())
        total += a.tries
    X, out = rng.normal(size=(48, 8)), np.empty(48)
    _norms_many(X, out, 1)
    rows.append(('einsum("ij,ij->i") (48 x 8)', (1, 3, 7, 8, 9, 16, 40), bad, total,
                 _ns(lambda: _norms_many(X, out, a.calls), a.calls),
                 _python_ns(lambda: np.einsum("ij,ij->i", X, X), a.calls)))
    x, y = rng.uniform(1e-3, 5.0, 100_000), np.full(100_000, -2.5)
    own_log, own_pow = _own_log_pow(x, y)
    own = (f"numba's own np.log and ** (the C library's): {(own_log != np.log(x)).sum()} and "
           f"{(own_pow != np.power(x, y)).sum()} of 100000 differ from numpy's")
    print(f"numpy {np.__version__}, numba {numba.__version__}")
    print(own)
    print(f"{'operation':<30} {'sizes':<24} {'differ':>12} {'ns in kernel':>13} "
          f"{'ns numpy call':>14}")
    for name, sz, b, n, k_ns, p_ns in rows:
        print(f"{name:<30} {','.join(map(str, sz)):<24} {f'{b} of {n}':>12} {k_ns:>13.0f} "
              f"{p_ns:>14.0f}")
    if DDOT is None:
        print("a @ b: skipped (this numpy ships no OpenBLAS in numpy.libs)")


if __name__ == "__main__":
    main()
