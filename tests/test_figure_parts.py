"""Figure parts of ``sitframe analyse`` checked without a whole report: evolving-situation
figures, a world's forced trajectories and goal."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.patches import Circle, FancyArrowPatch  # noqa: E402

from sitframe.analysis import situation_plots as SP  # noqa: E402
from sitframe.sim.draw import plot_world  # noqa: E402
from sitframe.sim.world import load_world  # noqa: E402


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def test_situation_counts_draw_one_step_line_per_trial():
    counts = {1: np.array([2, 3, 3, 4]), 0: np.array([2, 2, 1])}
    fig = SP.plot_situation_counts(counts, "Situations")
    lines = fig.axes[0].get_lines()
    assert [ln.get_label() for ln in lines] == ["trial 0", "trial 1"]  # in trial order
    assert lines[1].get_ydata().tolist() == [2, 3, 3, 4]
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == ["trial 0",
                                                                           "trial 1"]


def test_event_map_marks_each_kind_where_it_happened():
    world = load_world("training")
    events = {0: {"kind": np.array([0, 0, 2]), "pose": np.array([[1.0, 1.0, 0.0],
                                                                   [2.0, 1.0, 0.0],
                                                                   [3.0, 2.0, 0.0]])},
              1: {"kind": np.array([0, 3]), "pose": np.array([[1.5, 1.5, 0.0],
                                                              [2.5, 2.5, 0.0]])},
              2: {"kind": np.zeros(0, int), "pose": np.zeros((0, 3))}}
    fig = SP.plot_event_map(world, events, "Events")
    ax = fig.axes[0]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["create (3)", "merge (1)", "prune (1)"]
    created = ax.collections[[c.get_label() for c in ax.collections].index("create (3)")]
    assert sorted(map(tuple, created.get_offsets().tolist())) == [(1.0, 1.0), (1.5, 1.5),
                                                                   (2.0, 1.0)]


def test_world_plot_numbers_each_forced_leg_and_marks_the_goal():
    world = load_world("collect-1")
    legs = sum(t.shape[0] - 1 for t in world.trajectories)
    assert legs > 0
    ax = plot_world(world).axes[0]
    assert sum(isinstance(p, FancyArrowPatch) for p in ax.patches) == legs
    assert [t.get_text() for t in ax.texts][:legs] == \
        [str(i + 1) for t in world.trajectories for i in range(t.shape[0] - 1)]
    bare = plot_world(world, show_trajectories=False).axes[0]
    assert not any(isinstance(p, FancyArrowPatch) for p in bare.patches)
    goal = load_world("goal")
    circles = [p for p in plot_world(goal).axes[0].patches if isinstance(p, Circle)
               and p.get_facecolor()[:3] == matplotlib.colors.to_rgb("gold")]
    assert len(circles) == 1 and circles[0].center == tuple(goal.goal.position)
    assert circles[0].radius == goal.goal.radius
