"""Worlds: the TOML world format and its validating loader.

A world is a 2-D room made of zero-thickness wall polylines and closed
polygon obstacles, with a robot start pose, optional forced trajectories (for
data collection) and an optional goal. Units are metres; the start heading in
the file is in **degrees** (0 = +x, counter-clockwise positive) and becomes
radians in :attr:`World.start`.

File format
-----------
.. code-block:: toml

    name = "training"
    description = "13 m x 8 m room used to learn obstacle avoidance"

    [robot]
    start = [1.0, 1.0, 0.0]     # x [m], y [m], heading [deg]
    radius = 0.15               # optional: disc radius used to validate the start

    [[walls]]                   # polylines; a closed room repeats its first point
    points = [[0, 0], [13, 0], [13, 8], [0, 8], [0, 0]]

    [[obstacles]]               # closed polygons (first point not repeated)
    points = [[3, 3], [4, 3], [4, 4], [3, 4]]

    [[trajectories]]            # optional forced paths for data collection
    points = [[0.5, 0.5], [2.5, 0.5], [2.5, 5.5]]

    [goal]                      # optional
    position = [12.0, 7.0]
    radius = 0.3

    [meta]                      # optional free-form table, never interpreted

Every other key is an error (a typo in a world file should not be silently
ignored); free-form data goes under ``[meta]``.

*Inside the walls* means inside the outermost closed wall polygon (the one
with the largest area) and outside every other closed wall polygon (an inner
closed wall is a solid block). A world with no closed wall uses the bounding
box of its walls instead.

Generated rooms (``"gen:SEED"``, a file with a ``[generator]`` table) are drawn by
:mod:`sitframe.sim.roomgen` as world-file text and loaded here like any other.

Why one module of this size: the :class:`World`, its file format and the format's checks
are one thing; the checks use the world's own queries (inside, clearance) and a world is
only ever made by the loader, so split, each part would reach into the other's private
state.

Example
-------
>>> from sitframe.sim.world import load_world, list_worlds
>>> world = load_world("training")
>>> world.segments.shape[1]
4
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from functools import cache, cached_property
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from sitframe import params as P
from sitframe.errors import InputError, did_you_mean
from sitframe.sim import geometry as geo
from sitframe.sim import roomgen

__all__ = ["DEFAULT_ROBOT_RADIUS", "Goal", "World", "generate_room", "list_worlds", "load_world",
           "parse_world"]

#: Robot disc radius [m] used to validate start poses when the file gives none.
DEFAULT_ROBOT_RADIUS = 0.15

_TOP_KEYS = ("name", "description", "robot", "walls", "obstacles", "trajectories", "goal", "meta")
_ROBOT_KEYS = ("start", "radius")
_GOAL_KEYS = ("position", "radius")
_SHAPE_KEYS = ("points", "name")
_WORLDS_PACKAGE = "sitframe.worlds"

#: Largest coordinate or length [m] a world may use (beyond it distances lose
#: their precision and squares overflow).
MAX_COORD = 1e4
#: Most cells of the 0.5 m coverage grid over a world's bounds (a 1 km x 1 km room).
MAX_GRID_CELLS = 4_000_000
COVERAGE_CELL = 0.5


@dataclass(frozen=True)
class Goal:
    """A goal region: a disc.

    Attributes
    ----------
    position
        (2,) centre x, y [m].
    radius
        Radius [m]; the goal is reached when the robot's centre is within it.
    """

    position: np.ndarray
    radius: float = 0.3


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class World:
    """A validated, immutable world.

    Attributes
    ----------
    name
        Short name (the file's ``name`` key).
    description
        One-line human description.
    source
        Path of the file it was loaded from, or None for text.
    text
        The TOML source text (written to logs so a run can be reproduced).
    walls
        Tuple of (k, 2) wall polylines [m]; closed rooms repeat the first point.
    obstacles
        Tuple of (k, 2) closed obstacle polygons [m], first point not repeated.
    trajectories
        Tuple of (k, 2) forced-path polylines [m].
    start
        (3,) start pose x [m], y [m], theta [rad].
    goal
        The goal, or None.
    segments
        (S, 4) every wall and obstacle edge: x0, y0, x1, y1 [m].
    bounds
        (xmin, ymin, xmax, ymax) [m] of walls and obstacles.
    robot_radius
        Disc radius [m] the start pose was validated with.
    """

    name: str
    description: str
    source: str | None
    text: str
    walls: tuple[np.ndarray, ...]
    obstacles: tuple[np.ndarray, ...]
    trajectories: tuple[np.ndarray, ...]
    start: np.ndarray
    goal: Goal | None
    segments: np.ndarray
    bounds: tuple[float, float, float, float]
    robot_radius: float = DEFAULT_ROBOT_RADIUS
    meta: dict[str, Any] = field(default_factory=dict)

    # ------------------------------------------------------------------ cached geometry

    @cached_property
    def segment_set(self) -> geo.SegmentSet:
        """The :attr:`segments` with derived arrays cached, for fast queries."""
        return geo.SegmentSet(self.segments)

    @cached_property
    def _free_cells_memo(self) -> dict[tuple[float, float], np.ndarray]:
        """:meth:`free_cells` results by (cell, radius): coverage is scored per episode."""
        return {}

    @cached_property
    def _regions(self) -> tuple[np.ndarray | None, tuple[np.ndarray, ...]]:
        """(outer polygon or None, solid polygons: obstacles + inner closed walls)."""
        closed = [w[:-1] for w in self.walls if _is_closed(w)]
        outer = None
        solids = list(self.obstacles)
        if closed:
            areas = [abs(geo.polygon_area(c)) for c in closed]
            k = int(np.argmax(areas))
            outer = closed[k]
            solids += [c for i, c in enumerate(closed) if i != k]
        return outer, tuple(solids)

    # ------------------------------------------------------------------ queries

    def inside(self, xy: np.ndarray) -> np.ndarray:
        """Which points are inside the walls and outside every solid region.

        Parameters
        ----------
        xy
            (k, 2) points [m].

        Returns
        -------
        numpy.ndarray
            (k,) bool (clearance not considered; see :meth:`is_free`).
        """
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        ok = self._inside_outer(p)
        for poly in self._regions[1]:
            ok &= ~geo.point_in_polygon(p, poly)
        return ok

    def _inside_outer(self, p: np.ndarray) -> np.ndarray:
        """Which points of ``p`` (k, 2) are inside the outer wall (or the bounds)."""
        outer = self._regions[0]
        if outer is None:
            x0, y0, x1, y1 = self.bounds
            return (p[:, 0] > x0) & (p[:, 0] < x1) & (p[:, 1] > y0) & (p[:, 1] < y1)
        return geo.point_in_polygon(p, outer)

    def clearance(self, xy: np.ndarray) -> np.ndarray:
        """(k,) distance [m] from each point of ``xy`` (k, 2) to the nearest wall or edge."""
        return geo.min_distance(np.asarray(xy, dtype=np.float64).reshape(-1, 2), self.segment_set)

    def is_free(self, xy: np.ndarray, radius: float = DEFAULT_ROBOT_RADIUS) -> np.ndarray:
        """Whether a disc of ``radius`` centred at each point fits in free space.

        Parameters
        ----------
        xy
            (k, 2) disc centres [m].
        radius
            Disc radius [m] (0 tests the points themselves).

        Returns
        -------
        numpy.ndarray
            (k,) bool: inside the walls, not inside an obstacle, and clearance
            to every wall and obstacle edge ≥ ``radius``.
        """
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return self.inside(p) & (self.clearance(p) >= radius)

    def random_free_pose(
        self, rng: np.random.Generator, radius: float = DEFAULT_ROBOT_RADIUS, *,
        margin: float = 0.0, max_tries: int = 10_000,
    ) -> np.ndarray:
        """Draw a uniformly random free pose (position by rejection, heading uniform).

        Parameters
        ----------
        rng
            Source of randomness.
        radius
            Robot disc radius [m].
        margin
            Extra clearance [m] beyond ``radius``.
        max_tries
            Candidate positions to try before giving up.

        Returns
        -------
        numpy.ndarray
            (3,) pose x [m], y [m], theta [rad] in [-pi, pi).

        Raises
        ------
        InputError
            If no free position is found (the world is too cramped for the disc).
        """
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        x0, y0, x1, y1 = self.bounds
        tried = 0
        while tried < max_tries:
            n = min(256, max_tries - tried)
            cand = rng.uniform((x0, y0), (x1, y1), size=(n, 2))
            ok = np.flatnonzero(self.is_free(cand, radius + margin))
            tried += n
            if ok.size:
                xy = cand[ok[0]]
                return np.array([xy[0], xy[1], rng.uniform(-math.pi, math.pi)])
        raise InputError(
            f"found no free pose for a disc of radius {radius + margin:g} m in {max_tries} tries;"
            " expected a world with open space",
            file=self.source, key=None,
        )

    def free_cells(self, cell: float = 0.5, radius: float = DEFAULT_ROBOT_RADIUS) -> np.ndarray:
        """Centres of the grid cells whose centre is free (for coverage metrics).

        The grid has square cells of side ``cell`` [m] anchored at the lower
        left corner of :attr:`bounds`. Reachability is not checked: a free
        pocket walled off from the start still counts. The same test as
        :meth:`is_free`, computed per obstacle and per edge on the cells of
        its bounding box only (time proportional to the room plus the
        obstacles, not to their product).

        Returns
        -------
        numpy.ndarray
            (n, 2) cell centres [m], read-only: computed once per world, cell and
            radius (goal episodes score coverage once per episode).

        Raises
        ------
        ValueError
            ``cell`` is not positive or the grid would exceed about
            :data:`MAX_GRID_CELLS` cells of 0.5 m.
        """
        if not cell > 0:
            raise ValueError(f"cell must be > 0 metres, got {cell!r}")
        x0, y0, x1, y1 = self.bounds
        n_cells = math.ceil((x1 - x0) / cell) * math.ceil((y1 - y0) / cell)
        if n_cells > MAX_GRID_CELLS * max(1.0, (COVERAGE_CELL / cell) ** 2):
            raise ValueError(f"a {cell:g} m grid over the world has {n_cells} cells; expected "
                             f"at most {MAX_GRID_CELLS} cells of {COVERAGE_CELL:g} m")
        key = (float(cell), float(radius))
        if key not in self._free_cells_memo:
            free = self._free_cells(cell, radius)
            free.setflags(write=False)
            self._free_cells_memo[key] = free
        return self._free_cells_memo[key]

    def _free_cells(self, cell: float, radius: float) -> np.ndarray:
        """:meth:`free_cells`, computed (the arguments checked)."""
        x0, y0, x1, y1 = self.bounds
        xs = np.arange(x0 + cell / 2, x1, cell)
        ys = np.arange(y0 + cell / 2, y1, cell)
        gx, gy = np.meshgrid(xs, ys)
        c = np.stack([gx.ravel(), gy.ravel()], axis=1)

        def cells_in(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
            """Flat indices of the cells whose centre lies in the box [lo, hi]."""
            i = np.arange(np.searchsorted(xs, lo[0], "left"), np.searchsorted(xs, hi[0], "right"))
            j = np.arange(np.searchsorted(ys, lo[1], "left"), np.searchsorted(ys, hi[1], "right"))
            return (j[:, None] * xs.size + i[None, :]).ravel()

        outer, solids = self._regions
        ok = self._inside_outer(c)
        for poly in solids:  # a point outside a polygon's bounding box is outside it
            idx = cells_in(poly.min(axis=0), poly.max(axis=0))
            ok[idx] &= ~geo.point_in_polygon(c[idx], poly)
        seg = self.segments
        pad = radius * (1 + 1e-9) + 1e-12  # beyond the padded box a cell is farther than radius
        lo = np.minimum(seg[:, :2], seg[:, 2:]) - pad
        hi = np.maximum(seg[:, :2], seg[:, 2:]) + pad
        for k in range(seg.shape[0]):
            idx = cells_in(lo[k], hi[k])
            idx = idx[ok[idx]]
            if idx.size:
                ok[idx] &= geo.point_segment_distance(c[idx], seg[k:k + 1])[:, 0] >= radius
        return c[ok]

    def with_start(self, pose: np.ndarray) -> World:
        """Return a copy with another start pose (x [m], y [m], theta [rad]), validated."""
        p = np.asarray(pose, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"pose must be 3 finite numbers (x, y, theta_rad), got {pose!r}")
        _check_start(self, p[:2], self.robot_radius, file=self.source)
        return dataclasses.replace(self, start=_readonly(p))

    def __repr__(self) -> str:
        x0, y0, x1, y1 = self.bounds
        return (
            f"World({self.name!r}, {x1 - x0:g} m x {y1 - y0:g} m, {len(self.walls)} walls, "
            f"{len(self.obstacles)} obstacles, {self.segments.shape[0]} segments)"
        )


# ----------------------------------------------------------------------------- loading


def list_worlds() -> list[str]:
    """Names of the shipped worlds (files in the ``sitframe.worlds`` package), sorted."""
    root = resources.files(_WORLDS_PACKAGE)
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_world(name_or_path: str | Path | World) -> World:
    """Load a shipped world by name, or a world file by path.

    Parameters
    ----------
    name_or_path
        A shipped name such as ``"training"`` (see :func:`list_worlds`) or a
        path to a ``.toml`` file.

    Raises
    ------
    InputError
        Unknown name (lists the available names), missing file, or any
        validation problem (see :func:`parse_world`).
    """
    if isinstance(name_or_path, World):
        return name_or_path
    if not isinstance(name_or_path, str | Path):
        raise TypeError(f"expected a world name or path, got {type(name_or_path).__name__}")
    path = Path(name_or_path)
    looks_like_path = (
        isinstance(name_or_path, Path) or path.suffix == ".toml" or len(path.parts) > 1
        or "/" in str(name_or_path)
    )
    if looks_like_path or path.is_file():
        if path.exists() and not path.is_file():
            what = "a folder" if path.is_dir() else "not a regular file"
            raise InputError(f"the world path is {what}; expected a .toml world file or one of "
                             f"the shipped worlds: {', '.join(list_worlds())}", file=str(path))
        if not path.is_file():
            raise InputError(
                f"world file not found; expected an existing .toml file or one of the shipped "
                f"worlds: {', '.join(list_worlds())}",
                file=str(path),
            )
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read world file: {exc}", file=str(path)) from exc
        return parse_world(text, file=str(path))
    name = str(name_or_path)
    if name.startswith(roomgen.PREFIX):
        return _generated_world(name)
    names = list_worlds()
    if name not in names:
        raise InputError(
            f"unknown world {name!r}{did_you_mean(name, names)}; expected a path to a .toml "
            f"file or one of: {', '.join(names)}"
        )
    return _shipped_world(name)


def generate_room(seed: int, **params: Any) -> World:
    """The generated room of ``seed`` (:mod:`sitframe.sim.roomgen`), a validated world.

    Parameters
    ----------
    seed
        Any integer in [0, 2**63): the same seed and parameters give the same room, bit for
        bit.
    **params
        ``name``, ``description``, and any generator parameter
        (:data:`sitframe.sim.roomgen.GENERATOR`: ``width``, ``height``, ``dividers``,
        ``door``, ``obstacles``, ``obstacle_size``, ``gap``, ``robot_radius``; metres,
        ranges as ``[lo, hi]``).

    Raises
    ------
    InputError
        A parameter out of range or impossible, naming the key and the limit.

    Examples
    --------
    >>> room = generate_room(3)
    >>> room.name, room == generate_room(3), room.text == generate_room(3).text
    ('gen:3', False, True)
    """
    return parse_world(roomgen.room_text(seed, **params), file=params.get("file"))


@cache
def _generated_world(name: str) -> World:
    """The room ``"gen:SEED"`` names (:mod:`sitframe.sim.roomgen`), generated once per
    process."""
    seed = name[len(roomgen.PREFIX):]
    if not (seed.isascii() and seed.isdigit()) or int(seed) >= 2**63:
        raise InputError(f"unknown world {name!r}; expected {roomgen.PREFIX}SEED with SEED a "
                         "whole number in [0, 2**63), e.g. \"gen:1000000\"")
    return generate_room(int(seed))


@cache
def _shipped_world(name: str) -> World:
    """A shipped world, parsed once per process (package data does not change; a World is
    immutable, so every caller may share it)."""
    res = resources.files(_WORLDS_PACKAGE) / f"{name}.toml"
    return parse_world(res.read_text(encoding="utf-8"), file=str(res))


def parse_world(text: str, *, file: str | None = None) -> World:
    """Parse and validate the TOML text of a world.

    Parameters
    ----------
    text
        TOML source.
    file
        Where it came from, for error messages.

    Raises
    ------
    InputError
        Not TOML (with tomllib's message and line), empty, missing or unknown
        keys, wrong types, non-finite coordinates, polygons with < 3 points,
        polylines with < 2 points, self-intersecting polygons, a start pose
        inside/touching an obstacle or wall or outside the walls, a goal
        outside the walls or inside an obstacle. The message names the key
        path (e.g. ``obstacles[1].points``) and what was expected.
    """
    data = _toml_table(text, file)
    if "generator" in data:
        return _generated_file(data, file)
    P.known_keys(data, _TOP_KEYS, file=file)
    for req in ("name", "robot", "walls"):
        if req not in data:
            what = {"name": 'name = "..."', "robot": "[robot] with start = [x, y, heading_deg]",
                    "walls": "at least one [[walls]] with points = [[x, y], ...]"}[req]
            raise InputError(f"missing required key {req!r}; expected {what}", file=file, key=req)

    name = data["name"]
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"expected a non-empty string, got {name!r}", file=file, key="name")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise InputError(f"expected a string, got {description!r}", file=file, key="description")

    robot = _table(data, "robot", _ROBOT_KEYS, "start", "[x, y, heading_deg]", file)
    start = _numbers(robot["start"], 3, "robot.start", file, what="[x, y, heading_deg]")
    radius = DEFAULT_ROBOT_RADIUS
    if "radius" in robot:
        radius = _number(robot["radius"], "robot.radius", file, positive=True)

    walls = tuple(_shapes(data, "walls", file, min_points=2, polygon=False))
    if not walls:
        raise InputError(
            "expected at least one [[walls]] entry with points = [[x, y], ...]",
            file=file, key="walls",
        )
    obstacles = tuple(_shapes(data, "obstacles", file, min_points=3, polygon=True))
    trajectories = tuple(_shapes(data, "trajectories", file, min_points=2, polygon=False))

    goal = None
    if "goal" in data:
        g = _table(data, "goal", _GOAL_KEYS, "position", "[x, y]", file)
        pos = _numbers(g["position"], 2, "goal.position", file, what="[x, y]")
        goal = Goal(_readonly(pos), _number(g.get("radius", 0.3), "goal.radius", file,
                                                      positive=True))

    meta = data.get("meta", {})
    if not isinstance(meta, dict):
        raise InputError(f"expected a table [meta], got {meta!r}", file=file, key="meta")

    segs = [geo.polyline_segments(w) for w in walls] + [geo.polygon_edges(o) for o in obstacles]
    segments = _readonly(np.concatenate(segs, axis=0))
    pts = np.concatenate(list(walls) + list(obstacles), axis=0)
    bounds = (float(pts[:, 0].min()), float(pts[:, 1].min()),
              float(pts[:, 0].max()), float(pts[:, 1].max()))

    world = World(
        name=name.strip(),
        description=description.strip(),
        source=file,
        text=text,
        walls=walls,
        obstacles=obstacles,
        trajectories=trajectories,
        start=_readonly([start[0], start[1], math.radians(start[2])]),
        goal=goal,
        segments=segments,
        bounds=bounds,
        robot_radius=radius,
        meta=meta,
    )
    _check_extent(world, file)
    _check_start(world, start[:2], radius, file=file)
    if goal is not None:
        gp = goal.position[None, :]
        if not world.inside(gp)[0]:
            where = "inside an obstacle" if _in_obstacle(world, gp) else "outside the walls"
            raise InputError(
                f"goal position {goal.position.tolist()} is {where}; expected a point in free "
                "space inside the walls",
                file=file, key="goal.position",
            )
    return world


def _toml_table(text: str, file: str | None) -> dict[str, Any]:
    """The TOML table of a world file's ``text`` (an :class:`InputError` with the line)."""
    if not isinstance(text, str):
        raise TypeError(f"text must be a str of TOML, got {type(text).__name__}")
    if not text.strip():
        raise InputError(
            "world file is empty; expected TOML with name, [robot] start and [[walls]]", file=file
        )
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        if "line" not in msg:  # tomllib says "at end of document": give the line anyway
            msg = f"{msg}, line {text.count(chr(10)) + (not text.endswith(chr(10)))}"
        raise InputError(f"not valid TOML: {msg}", file=file) from exc


def _generated_file(data: dict[str, Any], file: str | None) -> World:
    """A world file holding a ``[generator]`` table (and at most a name and description):
    the room it describes (:func:`sitframe.sim.roomgen.generate_room`)."""
    P.known_keys(data, ("name", "description", "generator"), file=file)
    gen = data["generator"]
    if not isinstance(gen, dict):
        raise InputError(f"expected a table [generator] with seed = N, got {gen!r}",
                         file=file, key="generator")
    table = roomgen.room_parameters(gen, file=file)
    for key in ("name", "description"):
        if not isinstance(data.get(key, ""), str):
            raise InputError(f"expected a string, got {data[key]!r}", file=file, key=key)
    name = data.get("name", "").strip() or f"{roomgen.PREFIX}{table['seed']}"
    text = roomgen.generated_text(table, name=name, description=data.get("description", ""),
                                  file=file)
    return parse_world(text, file=file)


# ----------------------------------------------------------------------------- validation helpers


def _check_extent(world: World, file: str | None) -> None:
    """A coverage grid of bounded size, obstacles inside the walls, trajectories that stay
    inside the room without crossing a wall or an obstacle edge."""
    x0, y0, x1, y1 = world.bounds
    cells = math.ceil((x1 - x0) / COVERAGE_CELL) * math.ceil((y1 - y0) / COVERAGE_CELL)
    if cells > MAX_GRID_CELLS:
        raise InputError(f"the world spans {x1 - x0:g} m x {y1 - y0:g} m, {cells} cells of the "
                         f"{COVERAGE_CELL:g} m coverage grid; expected at most {MAX_GRID_CELLS} "
                         "(about 1 km x 1 km)", file=file, key="walls")
    outer = world._regions[0]
    if outer is not None:
        for i, ob in enumerate(world.obstacles):
            if not geo.point_in_polygon(ob, outer).any():
                raise InputError("obstacle lies outside the walls; expected every obstacle "
                                 "inside the outermost closed wall", file=file,
                                 key=f"obstacles[{i}].points")
    for i, traj in enumerate(world.trajectories):
        out = np.flatnonzero(~world.inside(traj))
        if out.size:
            raise InputError(f"point {int(out[0])} {traj[out[0]].tolist()} is outside the walls "
                             "or inside an obstacle; expected a path through free space",
                             file=file, key=f"trajectories[{i}].points")
        hits = geo.segments_intersect(geo.polyline_segments(traj), world.segments)
        if hits.any():
            j = int(np.flatnonzero(hits.any(axis=1))[0])
            raise InputError(f"segment {j} ({traj[j].tolist()} -> {traj[j + 1].tolist()}) "
                             "crosses a wall or an obstacle edge; expected a path through free "
                             "space", file=file, key=f"trajectories[{i}].points")


def _is_closed(points: np.ndarray) -> bool:
    return points.shape[0] >= 4 and bool(np.all(points[0] == points[-1]))


def _in_obstacle(world: World, xy: np.ndarray) -> bool:
    return any(bool(geo.point_in_polygon(xy, o)[0]) for o in world._regions[1])


def _table(data: dict[str, Any], name: str, keys: tuple[str, ...], required: str,
           shape: str, file: str | None) -> dict[str, Any]:
    """The table ``[name]`` with only ``keys`` and its ``required`` key (``= shape``) present."""
    t = data[name]
    if not isinstance(t, dict):
        raise InputError(f"expected a table [{name}] with {required} = {shape}, got {t!r}",
                         file=file, key=name)
    P.known_keys(t, keys, prefix=name, file=file)
    if required not in t:
        raise InputError(f"missing required key '{required}'; expected {required} = {shape}",
                         file=file, key=f"{name}.{required}")
    return t


def _check_start(world: World, xy: np.ndarray, radius: float, *, file: str | None) -> None:
    p = np.asarray(xy, dtype=np.float64).reshape(1, 2)
    where = [round(float(v), 6) for v in p[0]]
    if _in_obstacle(world, p):
        raise InputError(
            f"start position {where} is inside an obstacle; expected a point in free space",
            file=file, key="robot.start",
        )
    if not world.inside(p)[0]:
        raise InputError(
            f"start position {where} is outside the walls; expected a point inside the "
            "outermost closed wall",
            file=file, key="robot.start",
        )
    c = float(world.clearance(p)[0])
    if c < radius:
        raise InputError(
            f"start position {where} is {c:.3f} m from the nearest wall or obstacle edge; expected "
            f"at least the robot radius {radius:g} m so the robot does not start touching it",
            file=file, key="robot.start",
        )


def _number(v: Any, key: str, file: str | None, *, positive: bool = False) -> float:
    """A coordinate or length (metres; degrees for a heading) within ±:data:`MAX_COORD`."""
    try:
        return float(P.number(key, v, lo=0.0 if positive else -MAX_COORD, hi=MAX_COORD,
                              lo_open=positive))
    except InputError as exc:
        raise exc.at(file=file) from None


def _numbers(v: Any, n: int, key: str, file: str | None, *, what: str) -> np.ndarray:
    if not isinstance(v, list) or len(v) != n:
        raise InputError(f"expected {what} ({n} numbers), got {v!r}", file=file, key=key)
    return np.array([_number(x, f"{key}[{i}]", file) for i, x in enumerate(v)])


def _shapes(
    data: dict[str, Any], key: str, file: str | None, *, min_points: int, polygon: bool
) -> list[np.ndarray]:
    if key not in data:
        return []
    items = data[key]
    if not isinstance(items, list) or not all(isinstance(it, dict) for it in items):
        raise InputError(
            f"expected an array of tables [[{key}]] each with points = [[x, y], ...], "
            f"got {items!r}",
            file=file, key=key,
        )
    out = []
    kind = "polygon" if polygon else "polyline"
    for i, item in enumerate(items):
        where = f"{key}[{i}]"
        P.known_keys(item, _SHAPE_KEYS, prefix=where, file=file)
        if "points" not in item:
            raise InputError(
                "missing required key 'points'; expected points = [[x, y], ...]",
                file=file, key=f"{where}.points",
            )
        raw = item["points"]
        if not isinstance(raw, list):
            raise InputError(
                f"expected a list of [x, y] points, got {raw!r}", file=file, key=f"{where}.points"
            )
        pts = np.array(
            [_numbers(p, 2, f"{where}.points[{j}]", file, what="[x, y]") for j, p in enumerate(raw)]
        ).reshape(-1, 2)
        if polygon and pts.shape[0] >= 2 and np.all(pts[0] == pts[-1]):
            pts = pts[:-1]  # tolerate a repeated closing point
        if pts.shape[0] < min_points:
            raise InputError(
                f"{kind} needs at least {min_points} points, got {pts.shape[0]}",
                file=file, key=f"{where}.points",
            )
        closed = polygon or (key == "walls" and _is_closed(pts))
        ring = pts if polygon else (pts[:-1] if closed else pts)
        if closed and ring.shape[0] < 3:
            raise InputError(
                f"closed {kind} needs at least 3 distinct points, got {ring.shape[0]}",
                file=file, key=f"{where}.points",
            )
        # Forced trajectories may loop and cross themselves; open walls may only
        # not repeat a point; polygons and closed walls must be simple.
        bad = None
        if closed:
            bad = geo.polygon_self_intersection(ring, closed=True)
        elif key != "trajectories":
            rep = np.flatnonzero(np.all(pts[1:] == pts[:-1], axis=1))
            bad = (int(rep[0]) + 1,) * 2 if rep.size else None
        if bad is not None:
            a, b = bad
            msg = (f"repeated point at index {a}" if a == b else
                   f"edges {a} and {b} touch or cross")
            raise InputError(
                f"self-intersecting {kind}: {msg}; expected a simple {kind} "
                "(no repeated points, no crossing edges)",
                file=file, key=f"{where}.points",
            )
        out.append(_readonly(pts))
    return out
