"""Quality figures computed from per-iteration arrays (no simulation here).

All take plain numpy arrays so that analysis code can call them on arrays
read back from a log.
"""

from __future__ import annotations

import numpy as np

from sitframe.world import World


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


def spl(success: np.ndarray, straight: np.ndarray, path: np.ndarray) -> float:
    """Success weighted by path length: mean of ``S * l / max(p, l)`` over episodes."""
    success = np.asarray(success, dtype=float)
    straight = np.asarray(straight, dtype=float)
    path = np.asarray(path, dtype=float)
    if success.size == 0:
        return float("nan")
    return float(np.mean(success * straight / np.maximum(path, straight)))
