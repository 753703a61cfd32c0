"""What decides a trial's bits beyond sitframe's code: numpy, its SIMD loops, its BLAS.

A run's results are bit-identical across workers; across *machines* that holds only for
the same versions of sitframe, numpy and the plugins **and the same numpy SIMD targets and
BLAS kernels** (:func:`arithmetic`): numpy picks its sin, cos, exp, log and power loops at
run time by the CPU's features, and OpenBLAS its dot-product kernels; an
AVX-512 loop or kernel differs from the AVX2 one in the last bit of some
results, and a closed loop of robot and learner carries such a bit into a
different trajectory within a few hundred iterations. A log records them
(``versions``: ``numpy``, ``numpy_simd``, ``blas``); ``--resume`` and a Dask
cluster refuse to mix two arithmetics. Both choices can be overridden before
numpy is imported: ``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL
AVX512_SPR"`` turns numpy's AVX-512 targets off and ``OPENBLAS_CORETYPE=Haswell``
makes OpenBLAS use its AVX2 kernels; only both together make an AVX-512
machine compute as an AVX2 one.
"""

from __future__ import annotations

import functools
import os

from sitframe.errors import InputError


def numpy_simd() -> str:
    """numpy's SIMD targets in this process: its baseline and the dispatch targets it uses.

    E.g. ``"X86_V2 + X86_V3 X86_V4 AVX512_ICL"`` on an AVX-512 machine,
    ``"X86_V2 + X86_V3"`` on an AVX2 one or under
    ``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR"``. Two processes
    with the same numpy version and the same value compute the same bits.
    """
    import numpy as np

    umath = getattr(getattr(np, "_core", None), "_multiarray_umath", None) or \
        np.core._multiarray_umath  # (numpy < 2)
    found = getattr(umath, "__cpu_features__", {})
    used = [f for f in getattr(umath, "__cpu_dispatch__", []) if found.get(f)]
    return f"{' '.join(getattr(umath, '__cpu_baseline__', []))} + {' '.join(used) or '-'}"


@functools.cache  # (fixed when numpy loads; Dask asks again before every task)
def blas() -> str:
    """numpy's BLAS in this process: library, version and the kernel it picked for this CPU.

    E.g. ``"openblas 0.3.31.188.0 Haswell"`` (``threadpoolctl``'s view of the
    loaded libraries; numpy's own copy where a wheel bundles one, since scipy may
    load another). OpenBLAS picks its kernels at load time by the CPU, as numpy
    its SIMD loops, and ``np.dot`` and ``@`` go through them: under
    ``OPENBLAS_CORETYPE=Sandybridge`` instead of the ``Haswell`` kernels it
    picks on an AVX2 CPU, ``sitframe run obstacle-avoidance-12`` writes another
    log (666 datasets differ, the clustering already). ``"-"`` if none is loaded.
    """
    import numpy  # noqa: F401  (threadpoolctl sees only loaded libraries)
    from threadpoolctl import threadpool_info

    libs = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    own = [i for i in libs if os.path.basename(os.path.dirname(i.get("filepath", "")))
           .startswith("numpy")]
    keys = ("internal_api", "version", "architecture")
    names = {" ".join(str(i[k]) for k in keys if i.get(k)) for i in own or libs}
    return "; ".join(sorted(names)) or "-"


def arithmetic_versions() -> dict[str, str]:
    """This process's ``versions`` entries that decide a trial's bits beyond sitframe's code."""
    import numpy as np

    return {"numpy": np.__version__, "numpy_simd": numpy_simd(), "blas": blas()}


def arithmetic(versions: dict[str, str] | None = None, *,
               like: dict[str, str] | None = None) -> str:
    """What decides the bits of a trial beyond sitframe's own code: numpy's version, its SIMD
    targets and its BLAS (library, version, kernel), as one string.

    Of this process (``versions`` None), or of a log's ``versions`` (``""`` for a log
    written before they were recorded). ``like``: only what that log recorded (a log
    written before ``blas`` was recorded is compared on numpy and its SIMD targets)."""
    v = arithmetic_versions() if versions is None else versions
    if "numpy_simd" not in v:
        return ""
    text = f"numpy {v.get('numpy')}, SIMD {v['numpy_simd']}"
    return text + (f", BLAS {v['blas']}" if "blas" in v and "blas" in (like or v) else "")


def _parts(arith: str) -> tuple[str, str, str]:
    """(numpy version, SIMD targets, BLAS) of an :func:`arithmetic` string."""
    head, _, blas_ = arith.partition(", BLAS ")
    numpy_, _, simd = head.partition(", SIMD ")
    return numpy_, simd, blas_


def arithmetic_hint(have: str, want: str) -> str:
    """How to make a process with :func:`arithmetic` ``have`` compute as one with ``want``."""
    (hn, hs, hb), (wn, ws, wb) = _parts(have), _parts(want)
    if hn != wn:
        return wn
    hints = []
    if hs != ws:
        extra = set(hs.partition("+")[2].split()) - set(ws.partition("+")[2].split()) - {"-"}
        hints.append(f'NPY_DISABLE_CPU_FEATURES="{" ".join(sorted(extra))}" set before numpy '
                     "is imported" if extra else
                     "a machine whose CPU offers numpy the same SIMD targets")
    if hb != wb:
        h, w = hb.split(), wb.split()
        hints.append(f"OPENBLAS_CORETYPE={w[2]} set before numpy is imported, if this CPU runs "
                     "that kernel" if len(h) == len(w) == 3 and h[:2] == w[:2]
                     and h[0] == "openblas" else f"numpy with the BLAS {wb}")
    return " and ".join(hints)


def check_same_arithmetic(here: str, workers: dict[str, str]) -> None:
    """Refuse workers whose :func:`arithmetic` differs from this process's ``here``."""
    other = {w: a for w, a in workers.items() if a != here}
    if other:
        w, a = sorted(other.items())[0]
        raise InputError(f"worker {w} computes with {a}, this process with {here}: its trials "
                         "would not be bit-identical to a serial run's; expected the same on "
                         f"every worker (there: {arithmetic_hint(a, here)})", key="--scheduler")
