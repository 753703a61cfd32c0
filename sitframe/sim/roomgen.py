"""A seeded room generator: families of rooms to train, choose and judge in.

:func:`room_text` draws one room (:func:`sitframe.sim.world.generate_room` makes it a
world): a rectangular outline, partial dividers standing
out from its walls (like the thesis's novel rooms), and polygon obstacles. The same seed
and parameters give the same room, bit for bit, on every machine; any seed gives a valid
one:

- the outline is closed, every obstacle lies inside it, no two obstacles come closer than
  ``gap`` (nor an obstacle to a wall), so the robot passes between any two;
- every free place is reachable: the free space of the robot's disc, on a 0.1 m grid, is
  one connected region (a layout that walls off a pocket is drawn again);
- the start pose has ``START_MARGIN`` of clearance beyond the robot's radius.

Where a room is named
    Anywhere a world is named (a config's ``world``, ``collect.worlds``, an evaluation
    protocol's ``worlds``, ``sitframe evaluate LOG --world``, ``sitframe world show``),
    ``"gen:SEED"`` is the room of that seed with the default parameters. A world file
    whose only table is ``[generator]`` (``seed`` and any parameter of :data:`GENERATOR`)
    is the room those give; its ``name`` is optional::

        name = "wide-rooms-7"      # default "gen:7"
        [generator]
        seed = 7
        width = [12, 16]           # m, drawn uniformly
        obstacles = [6, 10]

Seed ranges (a convention of the benchmarks, not of the generator): rooms 1_000_000 on
train, 2_000_000 on choose (validation, development), 3_000_000 on judge; nothing that
trains, tunes or selects ever runs in the last.

A generated world's :attr:`~sitframe.sim.world.World.text` is its full geometry as a world
file (walls, obstacles, start) with the generator's parameters under ``[meta]``: a log holds
the room it ran in, not only the recipe.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import ndimage

from sitframe.errors import InputError
from sitframe.params import REQUIRED, Key, Table
from sitframe.sim import geometry as geo

__all__ = ["GENERATOR", "PREFIX", "generated_text", "room_parameters", "room_text"]

#: A world name ``PREFIX + "SEED"`` is the generated room of that seed.
PREFIX = "gen:"
#: Clearance [m] beyond the robot's radius at a generated room's start pose.
START_MARGIN = 0.3
#: Grid [m] on which a room's free space must be one connected region.
REACH_CELL = 0.1
#: Layouts drawn before a parameter set is declared impossible.
ATTEMPTS = 60
_SIDE = (0.0, 100.0)


def _range(value: Any, name: str, *, integer: bool = False) -> list[float]:
    """A ``[lo, hi]`` pair with ``lo <= hi`` (the kind's bounds checked before)."""
    if len(value) != 2 or value[0] > value[1]:
        raise InputError(f"expected [lo, hi] with lo <= hi, got {value!r}", key=name)
    if integer and not all(float(v).is_integer() for v in value):
        raise InputError(f"expected two whole numbers [lo, hi], got {value!r}", key=name)
    return [int(v) for v in value] if integer else [float(v) for v in value]


def _ints(value: Any, name: str) -> list[float]:
    return _range(value, name, integer=True)


#: The generator's parameters (a world file's ``[generator]`` table).
GENERATOR = Table("generator", (
    Key("seed", "integer", REQUIRED, "the room's seed: the same seed, the same room", lo=0,
        hi=2**63 - 1),
    Key("width", "numbers", [6.0, 10.0], "the room's extent along x, drawn uniformly in "
        "[lo, hi]", unit="m", lo=_SIDE[0], lo_open=True, hi=_SIDE[1],
        check=_range),
    Key("height", "numbers", [6.0, 10.0], "the room's extent along y, drawn uniformly in "
        "[lo, hi]", unit="m", lo=_SIDE[0], lo_open=True, hi=_SIDE[1],
        check=_range),
    Key("dividers", "numbers", [0, 3], "how many partial walls stand out from the outline "
        "(each leaves an opening of at least 'door')", lo=0, hi=20, check=_ints),
    Key("door", "number", 1.2, "the narrowest opening a divider leaves", unit="m", lo=0.0,
        lo_open=True, hi=_SIDE[1]),
    Key("obstacles", "numbers", [3, 9], "how many polygon obstacles", lo=0, hi=200,
        check=_ints),
    Key("obstacle_size", "numbers", [0.25, 0.8], "an obstacle's radius (centre to its "
        "farthest corner)", unit="m", lo=0.05, hi=_SIDE[1], check=_range),
    Key("gap", "number", 0.7, "the least free space between two obstacles and between an "
        "obstacle and a wall", unit="m", lo=0.0, lo_open=True, hi=_SIDE[1]),
    Key("robot_radius", "number", 0.15, "the robot disc the room must hold (start pose, "
        "gaps, doors, reachability)", unit="m", lo=0.0, lo_open=True, hi=5.0),
), doc="A generated room: ``seed`` and the ranges its layout is drawn from "
        "(:mod:`sitframe.sim.roomgen`).")


def room_parameters(table: dict[str, Any], *, file: str | None = None) -> dict[str, Any]:
    """``table`` (a ``[generator]`` table) checked and completed with the defaults.

    Beyond each key's own range: the robot must fit through ``gap`` and ``door`` and into
    the smallest room with its start margin, and ``obstacles`` of ``obstacle_size`` must be
    able to fit into the smallest room; else an :class:`InputError` naming the key and
    the limit.
    """
    p = GENERATOR.validate(table, file=file)
    d = 2 * p["robot_radius"]

    def fail(key: str, msg: str) -> None:
        raise InputError(msg, file=file, key=f"generator.{key}")

    for key in ("gap", "door"):
        if p[key] <= d:
            fail(key, f"{p[key]:g} m does not let the robot (a disc of {d:g} m) pass; expected "
                 f"more than {d:g} m (the robot's diameter)")
    need = d + 2 * START_MARGIN
    for key in ("width", "height"):
        if p[key][0] < need:
            fail(key, f"a room {p[key][0]:g} m across cannot hold the robot (a disc of {d:g} m "
                 f"with {START_MARGIN:g} m around it); expected at least {need:g} m")
    if p["dividers"][1] and min(p["width"][0], p["height"][0]) < p["door"] + 2 * p["gap"]:
        fail("dividers", f"a divider needs a room at least door + 2 gap = "
             f"{p['door'] + 2 * p['gap']:g} m across, the smallest is "
             f"{min(p['width'][0], p['height'][0]):g} m; expected dividers = [0, 0] or a larger "
             "width/height")
    area = p["width"][0] * p["height"][0]
    one = math.pi * (p["obstacle_size"][0] + p["gap"] / 2) ** 2
    fits = int(0.55 * area / one)  # a dense random packing of discs fills about 0.55
    if p["obstacles"][1] > fits:
        fail("obstacles", f"{p['obstacles'][1]} obstacles of radius "
             f"{p['obstacle_size'][0]:g} m with {p['gap']:g} m between them cannot fit in a "
             f"{p['width'][0]:g} m x {p['height'][0]:g} m room; expected at most {fits}")
    return p


def room_text(seed: int, *, name: str | None = None, description: str = "",
              file: str | None = None, **params: Any) -> str:
    """The world file of the room of ``seed`` (:func:`sitframe.sim.world.generate_room`
    parses it into a world).

    Parameters
    ----------
    seed
        Any integer in [0, 2**63): the same seed and parameters, the same room.
    name, description
        The world's name (default ``"gen:SEED"``) and description (default: what was drawn).
    file
        Where the parameters came from, for error messages.
    **params
        Any key of :data:`GENERATOR` but ``seed``; lengths in metres, ranges ``[lo, hi]``.

    Raises
    ------
    InputError
        A parameter out of range or impossible (the key and the limit named), or no valid
        layout in :data:`ATTEMPTS` draws.
    """
    p = room_parameters({"seed": seed, **params}, file=file)
    return generated_text(p, name=name or f"{PREFIX}{seed}", description=description,
                          file=file)


def generated_text(p: dict[str, Any], *, name: str, description: str = "",
                   file: str | None = None) -> str:
    """The world file of the room that checked parameters ``p`` give (see
    :func:`generate_room`)."""
    rng = np.random.default_rng(p["seed"])
    for _ in range(ATTEMPTS):
        layout = _layout(rng, p)
        if layout is None:
            continue
        if _reachable(layout, p["robot_radius"]):
            return _toml(layout, p, name, description or _describe(layout, p))
    raise InputError(f"no valid room in {ATTEMPTS} layouts of seed {p['seed']} (every free "
                     "place reachable, obstacles apart); expected fewer obstacles, a smaller "
                     "gap or obstacle_size, or larger rooms", file=file, key="generator")


def _layout(rng: np.random.Generator, p: dict[str, Any]) -> dict[str, Any] | None:
    """One draw: room size, dividers, obstacles, start; None when the obstacles or the start
    do not fit (drawn again)."""
    w = round(float(rng.uniform(*p["width"])), 2)
    h = round(float(rng.uniform(*p["height"])), 2)
    walls = [np.array([[0, 0], [w, 0], [w, h], [0, h], [0, 0]], float)]
    n_div = int(rng.integers(p["dividers"][0], p["dividers"][1] + 1))
    walls += [_divider(rng, w, h, p) for _ in range(n_div)]
    walls = [wall for wall in walls if wall is not None]
    segs = np.concatenate([geo.polyline_segments(x) for x in walls])
    obstacles: list[np.ndarray] = []
    discs: list[tuple[float, float, float]] = []
    for _ in range(int(rng.integers(p["obstacles"][0], p["obstacles"][1] + 1))):
        ob = _obstacle(rng, w, h, segs, discs, p)
        if ob is None:
            return None
        obstacles.append(ob)
    solid = np.concatenate([segs, *[geo.polygon_edges(o) for o in obstacles]])
    clear = p["robot_radius"] + START_MARGIN
    for _ in range(200):
        xy = rng.uniform((clear, clear), (w - clear, h - clear))
        if geo.min_distance(xy[None], solid)[0] >= clear and \
                not any(geo.point_in_polygon(xy[None], o)[0] for o in obstacles):
            heading = round(float(rng.uniform(-180, 180)), 1)
            return {"size": (w, h), "walls": walls, "obstacles": obstacles,
                    "start": (round(float(xy[0]), 3), round(float(xy[1]), 3), heading)}
    return None


def _divider(rng: np.random.Generator, w: float, h: float,
             p: dict[str, Any]) -> np.ndarray | None:
    """A wall standing out from one side of the outline, leaving at least ``door`` open."""
    vertical = bool(rng.integers(2))
    along, across = (w, h) if vertical else (h, w)  # position along one axis, length across
    margin = p["door"] + p["gap"]
    if along < 2 * margin or across < p["door"] + p["gap"]:
        return None
    at = round(float(rng.uniform(margin, along - margin)), 2)
    length = round(float(rng.uniform(0.35, 0.75)) * (across - p["door"]), 2)
    if length < p["gap"]:
        return None
    a, b = (0.0, length) if rng.integers(2) else (across, across - length)
    pts = [[at, a], [at, b]] if vertical else [[a, at], [b, at]]
    return np.array(pts, float)


def _obstacle(rng: np.random.Generator, w: float, h: float, segs: np.ndarray,
              discs: list[tuple[float, float, float]], p: dict[str, Any]) -> np.ndarray | None:
    """A star-shaped polygon of 3-6 corners placed ``gap`` from walls and other obstacles
    (by its enclosing disc); None if no place is found."""
    r = float(rng.uniform(*p["obstacle_size"]))
    k = int(rng.integers(3, 7))
    ang = np.sort(rng.uniform(0, 2 * math.pi) + 2 * math.pi * np.arange(k) / k
                  + rng.uniform(-0.25, 0.25, k) * 2 * math.pi / k)
    rad = r * rng.uniform(0.7, 1.0, k)
    gap = p["gap"]
    for _ in range(100):
        c = rng.uniform((r + gap, r + gap), (w - r - gap, h - r - gap)) \
            if w > 2 * (r + gap) and h > 2 * (r + gap) else None
        if c is None:
            return None
        if geo.min_distance(c[None], segs)[0] < r + gap:
            continue
        if any(math.hypot(c[0] - x, c[1] - y) < r + q + gap for x, y, q in discs):
            continue
        discs.append((float(c[0]), float(c[1]), r))
        pts = np.stack([c[0] + rad * np.cos(ang), c[1] + rad * np.sin(ang)], axis=1)
        return np.round(pts, 3)
    return None


def _reachable(layout: dict[str, Any], radius: float) -> bool:
    """Whether the free space of a disc of ``radius`` is one 4-connected region on a
    :data:`REACH_CELL` grid (two neighbouring free cells are joined by a free segment: both
    ends have clearance >= radius and the segment is shorter than 2 radius)."""
    w, h = layout["size"]
    xs = np.arange(REACH_CELL / 2, w, REACH_CELL)
    ys = np.arange(REACH_CELL / 2, h, REACH_CELL)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    c = np.stack([gx.ravel(), gy.ravel()], axis=1)
    segs = np.concatenate([geo.polyline_segments(x) for x in layout["walls"]]
                          + [geo.polygon_edges(o) for o in layout["obstacles"]])
    free = geo.min_distance(c, segs) >= radius
    for ob in layout["obstacles"]:
        free &= ~geo.point_in_polygon(c, ob)
    return ndimage.label(free.reshape(gx.shape))[1] == 1


def _describe(layout: dict[str, Any], p: dict[str, Any]) -> str:
    w, h = layout["size"]
    return (f"generated room (seed {p['seed']}): {w:g} m x {h:g} m, "
            f"{len(layout['walls']) - 1} dividers, {len(layout['obstacles'])} obstacles")


def _points(a: np.ndarray) -> str:
    return "[" + ", ".join(f"[{x:g}, {y:g}]" for x, y in a.tolist()) + "]"


def _toml(layout: dict[str, Any], p: dict[str, Any], name: str, description: str) -> str:
    """The world file of ``layout`` (its generator's parameters under ``[meta]``)."""
    x, y, heading = layout["start"]
    lines = [f"name = {_quote(name)}", f"description = {_quote(description)}", "",
             "[robot]", f"start = [{x:g}, {y:g}, {heading:g}]",
             f"radius = {p['robot_radius']:g}", ""]
    for wall in layout["walls"]:
        lines += ["[[walls]]", f"points = {_points(wall)}", ""]
    for ob in layout["obstacles"]:
        lines += ["[[obstacles]]", f"points = {_points(ob)}", ""]
    lines.append("[meta.generator]")
    for k in GENERATOR.keys:
        v = p[k.name]
        lines.append(f"{k.name} = {v!r}" if not isinstance(v, list)
                     else f"{k.name} = [{', '.join(f'{e:g}' for e in v)}]")
    return "\n".join(lines) + "\n"


def _quote(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'
