"""Labels for a set of situations: what each prototype looks like, and unique within the set.

:func:`~sitframe.situations.clustering.describe_prototype` names one prototype by its
shape (``"corridor"``, ``"wall on left"``, ...). A set of c prototypes often holds two of
one shape: a 16-situation Pioneer partition has five corridors, a 24-beam ring's ten
situations five. :func:`describe_prototypes` gives each prototype of a set a label no
other prototype of the set has, still read from its shape in the sensor's own bearings.
Where two share a description, the label adds, in this order and only as far as needed
to tell them apart:

1. the sides that are **open** in one and not in the others (``"open front-left"``:
   no reading below ``far`` in that sector; the sectors of ``describe_prototype``, with
   the rear split into rear-left, behind and rear-right for a sensor that sees there);
2. the **direction of the nearest** reading, in the sensor's own bearings
   (``"nearest 90° left"``, ``"nearest ahead"``, ``"nearest 30° left and right"`` when
   the mirrored beam is as near, within :data:`TIE_M`);
3. **how close** it is (``"at 0.35 m"``, in steps of :data:`STEP_M`: prototypes a
   centimetre apart read alike);
4. a **number** (``"#1"``, ``"#2"``) for prototypes that still read alike.

A detail is added only to a group of prototypes that read alike, and only if it differs
within the group, so a label is as short as the set allows. Labels are derived when a
log is analysed: they are not in the log, and changing them changes no log.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable

import numpy as np

from sitframe.situations.clustering import SECTORS_DEG, _ahead, describe_prototype

__all__ = ["STEP_M", "TIE_M", "describe_prototypes"]

#: Two readings within this many metres are "as near" (the nearest direction then names
#: both sides of a mirrored pair).
TIE_M = 0.05
#: How close the nearest reading is, in steps of this many metres.
STEP_M = 0.05


def describe_prototypes(centers: np.ndarray, angles_deg: np.ndarray, *, near: float = 0.5,
                        far: float = 0.9) -> list[str]:
    """One label per prototype of a set, no two alike (the module docstring).

    Parameters
    ----------
    centers : array_like, shape (c, d)
        Prototypes: a range per beam, metres.
    angles_deg : array_like, shape (d,)
        Beam bearings, degrees, positive = left: the sensor's own.
    near, far : float, metres
        Thresholds of :func:`~sitframe.situations.clustering.describe_prototype`
        (``far`` also decides which sides are open).

    Returns
    -------
    list of str
        ``c`` labels, pairwise different.
    """
    V = np.asarray(centers, dtype=np.float64)
    a = np.asarray(angles_deg, dtype=np.float64)
    if V.ndim != 2 or a.ndim != 1 or V.shape[1] != a.size:
        raise ValueError(f"centers must be (c, d) and angles_deg (d,) with the same d, got "
                         f"shapes {V.shape} and {a.shape}")
    labels = [describe_prototype(v, a, near=near, far=far) for v in V]
    a = (a + 180.0) % 360.0 - 180.0  # [-180, 180)
    details: list[Callable[[list[int]], dict[int, str]]] = [
        lambda group: _open_sides(V, a, group, far),
        lambda group: {i: _nearest_direction(V[i], a) for i in group},
        lambda group: {i: f"at {_step(V[i].min()):.2f} m" for i in group},
    ]
    _refine(list(range(len(labels))), labels, details, 0)
    return _numbered(labels)


def _refine(group: list[int], labels: list[str],
            details: list[Callable[[list[int]], dict[int, str]]], level: int) -> None:
    """Add detail ``level`` (and the next ones) to the prototypes of ``group`` that read
    alike, as long as a detail tells them apart."""
    for same in _alike(group, labels):
        if level >= len(details):
            return
        words = details[level](same)
        if len(set(words.values())) > 1:  # the detail tells some of them apart
            for i in same:
                if words[i]:
                    labels[i] = _join(labels[i], words[i])
        _refine(same, labels, details, level + 1)


def _alike(group: list[int], labels: list[str]) -> list[list[int]]:
    """The groups of two or more members of ``group`` with the same label."""
    by: dict[str, list[int]] = defaultdict(list)
    for i in group:
        by[labels[i]].append(i)
    return [g for g in by.values() if len(g) > 1]


def _join(label: str, word: str) -> str:
    """``label`` with a detail: ``"at ..."`` follows a direction directly, else a comma."""
    if word.startswith("at ") and ", nearest " in label:
        return f"{label} {word}"
    if word.startswith("at "):
        return f"{label}, nearest {word}"
    return f"{label}, {word}"


def _sectors(a: np.ndarray) -> dict[str, np.ndarray]:
    """The sectors (masks over the beams) the sensor covers: those of
    :func:`describe_prototype`, the rear split in three (rear-left 112.5-157.5 deg,
    behind beyond 157.5, rear-right)."""
    front, diag, side = SECTORS_DEG
    rear = 180.0 - front
    mag = np.abs(a)
    masks = {"ahead": mag <= front,
             "front-left": (a > front) & (a <= diag), "front-right": (a < -front) & (a >= -diag),
             "left": (a > diag) & (a <= side), "right": (a < -diag) & (a >= -side),
             "rear-left": (a > side) & (a <= rear), "rear-right": (a < -side) & (a >= -rear),
             "behind": mag > rear}
    return {name: m for name, m in masks.items() if m.any()}


def _open_sides(V: np.ndarray, a: np.ndarray, group: list[int], far: float) -> dict[int, str]:
    """Per prototype of ``group``: the sectors open in it (no reading below ``far``) that
    are not open in every prototype of the group (``""`` if none)."""
    sectors = _sectors(a)
    open_in = {i: [s for s, m in sectors.items() if _range(V[i], a, s, m, sectors, far) >= far]
               for i in group}
    common = set.intersection(*(set(s) for s in open_in.values()))
    return {i: ("open " + ", ".join(s for s in names if s not in common))
            if set(names) - common else "" for i, names in open_in.items()}


def _range(v: np.ndarray, a: np.ndarray, sector: str, mask: np.ndarray,
           sectors: dict[str, np.ndarray], far: float) -> float:
    """The range [m] of ``sector``: its nearest reading; ahead, what blocks the way as
    :func:`describe_prototype` decides it (a close side wall's readings in the ahead
    sector do not close it), so "open ahead" never contradicts the description."""
    if sector != "ahead" or "left" not in sectors or "right" not in sectors:
        return float(v[mask].min())
    left, right = (float(v[sectors[s]].min()) for s in ("left", "right"))
    return _ahead(v, a, mask, left if left < far else math.inf,
                  right if right < far else math.inf)


def _nearest_direction(v: np.ndarray, a: np.ndarray) -> str:
    """``"nearest <bearing>"`` of the nearest reading, in the sensor's own bearings; both
    sides when the mirrored beam reads as near (within :data:`TIE_M`)."""
    j = int(np.argmin(v))
    b = float(a[j])
    mirror = np.flatnonzero(np.isclose(a, -b) & (v <= v[j] + TIE_M))
    if 0 < abs(b) < 180 and mirror.size:
        return f"nearest {abs(b):g}° left and right"
    return f"nearest {_bearing(b)}"


def _bearing(b: float) -> str:
    """A bearing [deg, + = left] in words: ``"ahead"``, ``"behind"``, ``"30° left"``."""
    if math.isclose(b, 0.0, abs_tol=1e-9):
        return "ahead"
    if math.isclose(abs(b), 180.0, abs_tol=1e-9):
        return "behind"
    return f"{abs(b):g}° {'left' if b > 0 else 'right'}"


def _step(d: float) -> float:
    """``d`` [m] to the nearest multiple of :data:`STEP_M`."""
    return round(d / STEP_M) * STEP_M


def _numbered(labels: list[str]) -> list[str]:
    """Labels still alike get ``#1``, ``#2``, ... in order."""
    seen: dict[str, int] = defaultdict(int)
    total = defaultdict(int)
    for lb in labels:
        total[lb] += 1
    out = []
    for lb in labels:
        if total[lb] > 1:
            seen[lb] += 1
            out.append(f"{lb} #{seen[lb]}")
        else:
            out.append(lb)
    return out
