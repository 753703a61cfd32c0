"""Quality figures computed from per-iteration arrays (no simulation here).

All take plain numpy arrays so that analysis code can call them on arrays
read back from a log.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # (a world is read through free_cells and bounds only)
    from sitframe.sim.world import World


def collisions_per_1000(collision: np.ndarray, start: int = 0) -> float:
    """Collisions per 1000 iterations over ``collision[start:]`` (NaN if empty)."""
    tail = np.asarray(collision[start:], dtype=bool)
    return float(tail.sum() * 1000.0 / tail.size) if tail.size else float("nan")


def coverage(world: World, xy: np.ndarray, *, cell: float = 0.5, radius: float = 0.15) -> float:
    """Fraction of the world's free ``cell``-metre grid cells the robot's centre visited.

    A cell is *free* when its centre is free for the robot disc
    (:meth:`World.free_cells`); a cell is *visited* when some pose's (x, y)
    falls inside it. Visits to cells that are not free (possible near walls)
    are not counted.

    Parameters
    ----------
    world
        The world.
    xy
        (n, 2) robot positions, metres.
    """
    centres = world.free_cells(cell=cell, radius=radius)
    if len(centres) == 0:
        return float("nan")
    x0, y0 = world.bounds[0], world.bounds[1]
    free = {(int(i), int(j)) for i, j in np.floor((centres - [x0, y0]) / cell).astype(int)}
    ij = np.floor((np.asarray(xy)[:, :2] - [x0, y0]) / cell).astype(int)
    visited = {(int(i), int(j)) for i, j in np.unique(ij, axis=0)}
    return len(visited & free) / len(free)


def path_length(xy: np.ndarray) -> float:
    """Length of the polyline through the (n, 2) positions, metres."""
    d = np.diff(np.asarray(xy)[:, :2], axis=0)
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def heading_change_per_m(theta: np.ndarray, xy: np.ndarray) -> float:
    """Total absolute heading change (degrees) per metre travelled (path smoothness)."""
    dtheta = np.diff(np.unwrap(np.asarray(theta)))
    length = path_length(xy)
    return float(np.degrees(np.abs(dtheta).sum()) / length) if length > 0 else float("nan")


def spl(success: np.ndarray, reference: np.ndarray, path: np.ndarray) -> float:
    """Success weighted by path length: mean of ``S * l / max(p, l)`` over episodes.

    Parameters
    ----------
    success
        (n,) whether each episode reached the goal.
    reference
        (n,) the reference length ``l`` [m]: the shortest path (Anderson et al.
        2018), or the straight line; ``inf`` (the goal cannot be reached)
        counts 0, as every failure does.
    path
        (n,) the path driven ``p`` [m].
    """
    success = np.asarray(success, dtype=float)
    ref = np.asarray(reference, dtype=float)
    path = np.asarray(path, dtype=float)
    if success.size == 0:
        return float("nan")
    reachable = np.isfinite(ref)
    ref = np.where(reachable, ref, 0.0)
    return float(np.mean(np.where(reachable, success * ref / np.maximum(path, ref), 0.0)))


def frontal_between_prototypes(pose: np.ndarray, collision: np.ndarray, contact: np.ndarray,
                               memberships: np.ndarray, *, cone_deg: float = 30.0,
                               top: float = 0.5) -> np.ndarray:
    """(L,) whether each iteration's collision was frontal and began between prototypes.

    A collision at iteration ``t`` (the step from ``pose[t]``) is *frontal* when
    the contact point lies within ``cone_deg`` of the heading at ``pose[t]``, and
    *began between prototypes* when the reading the controller acted on at ``t``
    had no dominant situation: its largest membership is below ``top`` (the
    blended rules then turn by a compromise of their headings, which is the
    failure a finer situation can remove).

    Parameters
    ----------
    pose
        (L + 1, 3) or (L, 3) poses (x [m], y [m], theta [rad]); row ``t`` is the
        pose the iteration started from.
    collision
        (L,) bool.
    contact
        (L, 2) contact point [m] of each collision (NaN where none).
    memberships
        (L, c) memberships of each iteration's reading.
    """
    coll = np.asarray(collision, dtype=bool)
    L = coll.size
    p = np.asarray(pose, dtype=float)[:L]
    rel = np.asarray(contact, dtype=float)[:L] - p[:, :2]
    bearing = np.degrees(np.arctan2(rel[:, 1], rel[:, 0]) - p[:, 2])
    bearing = (bearing + 180.0) % 360.0 - 180.0
    with np.errstate(invalid="ignore"):
        frontal = np.abs(bearing) <= cone_deg
    return coll & frontal & (np.asarray(memberships)[:L].max(axis=1) < top)
