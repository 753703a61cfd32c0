"""Shortest collision-free paths of a disc in a world (the reference length of SPL).

SPL (Anderson et al. 2018, *On Evaluation of Embodied Navigation Agents*)
weights each success by ``l / max(p, l)``, where ``l`` is the length of the
*shortest path* from the start to the goal that the agent could drive.
Behind a wall or through a door that is longer than the straight line, so
:func:`shortest_path_length` computes it for the robot's disc:

1. If the straight segment keeps the disc clear of every wall and obstacle
   edge (:func:`segment_clear`), that is the shortest path: exact.
2. Otherwise the shortest path is made of straight pieces and arcs of the
   disc's radius around the corners it turns (the ends of walls, the
   corners of obstacles). Each arc is replaced by its circumscribed polygon:
   ``ARC_POINTS`` points around every vertex of the world's edges, at
   ``radius / cos(pi / ARC_POINTS)`` from it (the polygon's sides then touch
   the circle, never cut it); the points where the disc is free, with the
   start and the goal, form a visibility graph (an edge wherever the disc
   can move straight), searched by Dijkstra (``scipy.sparse.csgraph``).
   The result is the length of a path the disc can drive; it exceeds the
   true shortest one only on its arcs, by at most
   ``tan(pi/12) / (pi/12) - 1`` = 2.3 % of their length (about 1 cm for a
   U-turn around the end of a thin wall with the Pioneer's 0.15 m radius).

The graph of a world is built once per radius (a few tenths of a second)
and kept while the world object lives. :class:`PathDistance` keeps one
goal's distances to every arc point, so the shortest-path distance from any
point to that goal (a reward's potential, once per step) costs one
visibility check of the point instead of a graph search.
"""

from __future__ import annotations

import math
import weakref

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from sitframe.sim import geometry as geo
from sitframe.sim.kernels import kernels
from sitframe.sim.world import World

#: Points of the polygon that stands in for the disc's arc around each vertex.
ARC_POINTS = 12
_QUERIES: weakref.WeakKeyDictionary[World, dict[tuple[float, ...], float]] = (
    weakref.WeakKeyDictionary())
_MAX_QUERIES = 4096  # answers kept per world (a goal pair is asked when drawn, then scored)
_CHUNK = 4096  # moves checked per vectorised call (memory: CHUNK x edges)


def segment_clear(world: World, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """Whether a disc of ``radius`` moved straight from ``a`` to each ``b`` touches no edge.

    Parameters
    ----------
    world
        The world (its wall and obstacle edges).
    a
        (2,) start of the move [m].
    b
        (k, 2) ends of the moves [m].
    radius
        Disc radius [m].

    Returns
    -------
    numpy.ndarray
        (k,) bool: the distance from each segment ``a``-``b`` to every edge is at
        least ``radius`` (two segments are ``0`` apart when they cross, else
        the least distance from an endpoint of one to the other).
    """
    b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
    return _clear_moves(world, np.broadcast_to(np.asarray(a, dtype=np.float64).reshape(2),
                                               b.shape), b, radius)


def _clear_moves(world: World, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """(k,) whether the disc moved straight from each ``a`` (k, 2) to ``b`` (k, 2) is clear.

    Clear: no edge crosses the move, and no endpoint of either lies within
    ``radius`` of the other segment (which covers every touch as well).
    Checked ``_CHUNK`` moves at a time (memory: chunk x edges).
    """
    if a.shape[0] <= _CHUNK:
        return _clear_chunk(world, a, b, radius)
    return np.concatenate([_clear_chunk(world, a[c:c + _CHUNK], b[c:c + _CHUNK], radius)
                           for c in range(0, a.shape[0], _CHUNK)])


def _clear_chunk(world: World, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """:func:`_clear_moves` for one chunk."""
    e = world.segments
    if e.shape[0] == 0 or a.shape[0] == 0:
        return np.ones(a.shape[0], dtype=bool)
    kern = kernels()
    if kern is not None:  # the same test, operation by operation (bit twin)
        out = np.empty(a.shape[0], dtype=np.bool_)
        kern.clear_moves(np.ascontiguousarray(a), np.ascontiguousarray(b), e,
                         world.segment_set.packed, radius * (1 - 1e-9), out)
        return out
    px, py, qx, qy = a[:, :1], a[:, 1:], b[:, :1], b[:, 1:]  # moves as (k, 1) columns
    ax, ay, bx, by = e[:, 0], e[:, 1], e[:, 2], e[:, 3]  # edges as (E,) rows
    crossed = ((geo._orient(ax, ay, bx, by, px, py) * geo._orient(ax, ay, bx, by, qx, qy)) < 0) \
        & ((geo._orient(px, py, qx, qy, ax, ay) * geo._orient(px, py, qx, qy, bx, by)) < 0)
    k, r = a.shape[0], radius * (1 - 1e-9)
    ends = geo.point_segment_distance(np.vstack([a, b]), world.segment_set)  # (2k, E)
    near = (ends[:k] < r) | (ends[k:] < r)
    corners = geo.point_segment_distance(np.vstack([e[:, :2], e[:, 2:]]), np.hstack([a, b]))
    near |= ((corners[:e.shape[0]] < r) | (corners[e.shape[0]:] < r)).T  # (E, k) -> (k, E)
    return ~(crossed | near).any(axis=1)


def _clear_from(world: World, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """(k,) whether the disc moves straight from ``a`` (2,) to each of ``b`` (k, 2): the
    compiled kernel when it is loaded (the route planner and the path-distance reward ask
    this every step), else :func:`_clear_moves`. Only those two use it: a move that grazes
    an edge within rounding may be judged either way by the two, which no figure of a log
    of a preset without them depends on."""
    kern = kernels()
    if kern is None:
        return _clear_moves(world, np.broadcast_to(a, b.shape), b, radius)
    out = np.empty(b.shape[0], dtype=np.bool_)
    kern.clear_from(float(a[0]), float(a[1]), np.ascontiguousarray(b, dtype=np.float64),
                    world.segments, radius * (1 - 1e-9), out)
    return out


def shortest_path_length(world: World, start: np.ndarray, goal: np.ndarray, *,
                         radius: float) -> float:
    """Length [m] of the shortest path of a disc from ``start`` to ``goal`` (module docstring).

    Parameters
    ----------
    world
        The world.
    start, goal
        (2,) disc centres [m]; both should be free for the disc.
    radius
        Disc radius [m] (the robot's).

    Returns
    -------
    float
        The length [m]: exact when the straight line is clear, else within
        2.3 % of each arc the path turns; ``inf`` when no free path joins them.

    Raises
    ------
    ValueError
        ``radius`` is not a positive number.
    """
    if not radius > 0:
        raise ValueError(f"radius must be > 0 metres (the disc's), got {radius!r}")
    a = np.asarray(start, dtype=np.float64).reshape(2)
    b = np.asarray(goal, dtype=np.float64).reshape(2)
    key = (float(radius), *a.tolist(), *b.tolist())
    answers = _QUERIES.setdefault(world, {})
    if key not in answers:
        if len(answers) >= _MAX_QUERIES:
            answers.clear()
        answers[key] = route_graph(world, float(radius)).route(a, b)[1]
    return answers[key]


def _in_sight(world: World, p: np.ndarray, nodes: np.ndarray, radius: float) -> np.ndarray:
    """(n,) straight distance [m] from ``p`` to each node the disc reaches straight, else inf."""
    return np.where(segment_clear(world, p, nodes, radius), np.hypot(*(nodes - p).T), np.inf)


class PathDistance:
    """Shortest-path distance [m] of a disc from any point to one goal (module docstring).

    Parameters
    ----------
    world
        The world.
    goal
        (2,) the goal's centre [m].
    radius
        Disc radius [m] (the robot's), > 0.

    Notes
    -----
    Calling it with a point ``(2,)`` [m] returns the length of the shortest
    path of the disc from there to ``goal``: the straight line when it is
    clear, else through the arc points (within 2.3 % of each arc turned);
    ``inf`` when none joins them (no path, or the point or the goal is not
    free for the disc, e.g. in contact with a wall).

    Raises
    ------
    ValueError
        ``radius`` is not a positive number.
    """

    def __init__(self, world: World, goal: np.ndarray, radius: float) -> None:
        if not radius > 0:
            raise ValueError(f"radius must be > 0 metres (the disc's), got {radius!r}")
        self.world, self.radius = world, float(radius)
        self.goal = np.asarray(goal, dtype=np.float64).reshape(2)
        g = route_graph(world, self.radius)
        self.nodes = g.nodes
        db = _in_sight(world, self.goal, g.nodes, self.radius)
        #: (n,) shortest path from each arc point to the goal [m]
        self.to_goal = (g.between + db[None, :]).min(axis=1) if g.nodes.shape[0] else db
        self._targets = np.vstack([self.goal[None], g.nodes])

    def __call__(self, point: np.ndarray) -> float:
        p = np.asarray(point, dtype=np.float64).reshape(2)
        ok = _clear_from(self.world, p, self._targets, self.radius)
        if ok[0]:
            return float(math.hypot(*(self.goal - p)))
        if not ok[1:].any():
            return math.inf
        return float((np.hypot(*(self.nodes[ok[1:]] - p).T) + self.to_goal[ok[1:]]).min())


class RouteGraph:
    """A world's visibility graph for a disc, with the routes between its arc points.

    The arc points (``ARC_POINTS`` around every vertex of the world's edges, at the
    disc's radius) that :func:`shortest_path_length` and :class:`PathDistance` use too,
    and the shortest path
    between every two of them with its predecessors, so that a route (the list of
    waypoints, not only its length) costs one visibility check of the start and of
    the goal. Built once per world and radius (:func:`route_graph`).

    Parameters
    ----------
    world
        The world.
    radius
        Disc radius [m], > 0: the robot's radius plus the clearance a planner keeps.
    """

    def __init__(self, world: World, radius: float) -> None:
        if not radius > 0:
            raise ValueError(f"radius must be > 0 metres (the disc's), got {radius!r}")
        self.world, self.radius = world, float(radius)
        verts = np.unique(np.vstack([world.segments[:, :2], world.segments[:, 2:]]), axis=0)
        ang = 2 * math.pi * np.arange(ARC_POINTS) / ARC_POINTS
        ring = (radius / math.cos(math.pi / ARC_POINTS) * (1 + 1e-9)
                * np.stack([np.cos(ang), np.sin(ang)], axis=1))
        pts = (verts[:, None, :] + ring[None]).reshape(-1, 2)
        #: (n, 2) the arc points free for the disc
        self.nodes = pts[world.is_free(pts, radius)] if pts.size else pts
        n = self.nodes.shape[0]
        iu, ju = np.triu_indices(n, k=1)
        ok = _clear_moves(world, self.nodes[iu], self.nodes[ju], radius)
        lengths = np.zeros((n, n))
        d = np.hypot(*(self.nodes[iu[ok]] - self.nodes[ju[ok]]).T)
        lengths[iu[ok], ju[ok]] = d
        lengths[ju[ok], iu[ok]] = d
        if n:
            between, pred = dijkstra(csr_matrix(lengths), directed=True,
                                     return_predecessors=True)
        else:
            between, pred = np.zeros((0, 0)), np.zeros((0, 0), dtype=np.int32)
        #: (n, n) shortest path between every two arc points [m] (inf: not connected)
        self.between = between
        #: (n, n) the node before ``j`` on the shortest path from ``i`` (-9999: none)
        self.pred = pred

    def route(self, start: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, float]:
        """The shortest route of the disc from ``start`` to ``goal`` (both (2,) [m]).

        Returns
        -------
        (waypoints, length)
            ``waypoints`` (k, 2): the arc points the route turns at, then ``goal``
            (just ``goal`` when the straight line is clear); ``length`` [m] of the
            route from ``start``. ``(empty (0, 2), inf)`` when no route of this disc
            joins them (e.g. ``start`` touches a wall for this radius).
        """
        a = np.asarray(start, dtype=np.float64).reshape(2)
        b = np.asarray(goal, dtype=np.float64).reshape(2)
        if segment_clear(self.world, a, b[None], self.radius)[0]:
            return b[None].copy(), float(math.hypot(*(b - a)))
        if self.nodes.shape[0] == 0:
            return np.zeros((0, 2)), math.inf
        da = _in_sight(self.world, a, self.nodes, self.radius)
        db = _in_sight(self.world, b, self.nodes, self.radius)
        total = da[:, None] + self.between + db[None, :]
        flat = int(np.argmin(total))
        best = float(total.flat[flat])
        if not math.isfinite(best):
            return np.zeros((0, 2)), math.inf
        i, j = divmod(flat, self.nodes.shape[0])
        chain = [j]
        while chain[-1] != i:
            chain.append(int(self.pred[i, chain[-1]]))
        return np.vstack([self.nodes[chain[::-1]], b[None]]), best

    def visible(self, point: np.ndarray, targets: np.ndarray, radius: float | None = None
                ) -> np.ndarray:
        """(k,) whether the disc (``radius``, default the graph's) moves straight from
        ``point`` (2,) to each of ``targets`` (k, 2) without touching an edge."""
        return _clear_from(self.world, np.asarray(point, dtype=np.float64).reshape(2),
                           np.asarray(targets, dtype=np.float64).reshape(-1, 2),
                           self.radius if radius is None else radius)


_ROUTES: weakref.WeakKeyDictionary[World, dict[float, RouteGraph]] = weakref.WeakKeyDictionary()


def route_graph(world: World, radius: float) -> RouteGraph:
    """The :class:`RouteGraph` of ``world`` for a disc of ``radius``, built once per process
    (what :func:`shortest_path_length`, :class:`PathDistance` and the route planner share)."""
    per_world = _ROUTES.setdefault(world, {})
    if float(radius) not in per_world:
        per_world[float(radius)] = RouteGraph(world, float(radius))
    return per_world[float(radius)]


def shortest_route(world: World, start: np.ndarray, goal: np.ndarray, *,
                   radius: float) -> tuple[np.ndarray, float]:
    """The waypoints (k, 2) and length [m] of the shortest route of a disc of ``radius``
    from ``start`` to ``goal`` (:meth:`RouteGraph.route`; ``(empty, inf)`` when none)."""
    return route_graph(world, radius).route(start, goal)
