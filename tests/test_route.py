"""The route planner (sim.paths.shortest_route) and the route behaviour (goals behind doors)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitframe.contract.records import Context
from sitframe.plugins.goal import GoalBehaviour
from sitframe.plugins.route import RouteBehaviour
from sitframe.sim.paths import route_graph, segment_clear, shortest_path_length, shortest_route
from sitframe.sim.world import Goal, load_world, parse_world

#: Two rooms side by side; the door is at the bottom of the dividing wall, under a lip that
#: makes the wall's foot a pocket, the goal at the top of the other room: a straight-line
#: goal seeker slides down the wall into the pocket and stays there.
DOOR = """
name = "door"
[robot]
start = [1.0, 3.0, 0.0]
[[walls]]
points = [[0, 0], [8, 0], [8, 4], [0, 4], [0, 0]]
[[walls]]
points = [[3.0, 1.0], [4, 1.0], [4, 4]]
[goal]
position = [6.5, 3.2]
radius = 0.3
"""


def test_route_length_is_the_shortest_path_and_its_legs_are_clear():
    w = parse_world(DOOR)
    a, b = np.array([1.0, 3.0]), np.array([6.5, 3.2])
    wp, length = shortest_route(w, a, b, radius=0.4)
    assert math.isclose(length, shortest_path_length(w, a, b, radius=0.4), rel_tol=1e-12)
    assert np.array_equal(wp[-1], b) and wp[:, 1].min() < 1.0  # through the door, below y = 1
    legs = np.vstack([a, wp])
    assert all(segment_clear(w, p, q[None], 0.4)[0] for p, q in zip(legs[:-1], legs[1:],
                                                                   strict=True))
    assert math.isclose(length, float(np.hypot(*np.diff(legs, axis=0).T).sum()), rel_tol=1e-9)
    wp, length = shortest_route(w, a, np.array([3.0, 3.0]), radius=0.4)  # in sight: straight
    assert len(wp) == 1 and math.isclose(length, 2.0)
    wp, length = shortest_route(w, a, b, radius=0.6)  # the 1 m door is too narrow for it
    assert len(wp) == 0 and length == math.inf


def _ctx(w, xy, theta=0.0, it=1):
    pose = np.array([*xy, theta])
    return Context(it, pose, np.full(8, 3.0), np.ones(1), 3.0, w, Goal(np.array([6.5, 3.2]),
                                                                        0.3))


def test_route_heads_for_the_door_where_goal_seeking_heads_into_the_wall():
    w = parse_world(DOOR)
    route, goal = RouteBehaviour(), GoalBehaviour()
    at = _ctx(w, (2.0, 3.0), it=0)
    assert abs(goal.propose(at).heading_deg) < 5  # straight at the dividing wall
    assert route.propose(at).heading_deg < -30  # down, towards the door
    assert route.plans == 1 and route.waypoints[0][1] < 1.0


def test_route_replans_when_blocked():
    w = parse_world(DOOR)
    route = RouteBehaviour(replan_after=5)
    route.propose(_ctx(w, (2.0, 3.0), it=0))
    first = route.waypoints.copy()
    # pushed through to the other side of a wall corner: the waypoint is out of sight
    route.propose(_ctx(w, (2.0, 0.3)))
    assert route.plans >= 1
    # standing still: no approach to the waypoint for replan_after iterations -> re-plan
    plans = route.plans
    for it in range(2, 9):
        route.propose(_ctx(w, (2.0, 2.5), it=it))
    assert route.plans > plans and route.replans >= 1
    assert first.shape[1] == 2


def test_route_graph_is_built_once_per_world_and_radius():
    w = load_world("u-trap")
    assert route_graph(w, 0.4) is route_graph(w, 0.4)
    assert route_graph(w, 0.4) is not route_graph(w, 0.35)


@pytest.mark.parametrize("component", ["route", "goal"])
def test_a_goal_behind_a_door_is_reached_along_the_route_only(tmp_path, capsys, component):
    """Goal episodes from the world's start to its goal behind the dividing wall: the route
    behaviour reaches it, straight-line goal seeking does not."""
    from helpers import run_json

    (tmp_path / "door.toml").write_text(DOOR)
    cfg = tmp_path / f"{component}.toml"
    cfg.write_text(f"""
[experiment]
name = "door-{component}"
trials = 1
stages = ["evaluate"]
world = "door.toml"
default_speed = 0.15

[interpreter]
component = "fcm"
c = 2

[behaviours.goal]
component = "{component}"

[goal]
episodes = 1
pairs = "world"
timeout = 150
worlds = ["door.toml"]
""")
    fitted = _fitted_log(tmp_path)
    capsys.readouterr()
    doc = run_json(capsys, "run", str(cfg), "--out", str(tmp_path / f"{component}.h5"),
                   "--json", "--clusters-from", fitted)
    ev = doc["trials"][0]["evaluation"]
    assert ev["door/success_rate"] == (1.0 if component == "route" else 0.0)


def _fitted_log(tmp_path) -> str:
    """A log with 2 fitted situations (any will do: neither behaviour reads them)."""
    from helpers import run_config, small_config

    path = tmp_path / "fitted.h5"
    if not path.exists():
        run_config(tmp_path, small_config(c=2, trials=1, iterations=20), "fitted.h5")
    return str(path)
