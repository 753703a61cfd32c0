"""Draw a world to scale: walls, obstacles, forced trajectories, goal and start.

Headless-safe: figures are made with :class:`matplotlib.figure.Figure`
directly (no pyplot state, no GUI backend needed).

Example
-------
>>> from sitframe.sim.world import load_world
>>> from sitframe.sim.draw import plot_world
>>> fig = plot_world(load_world("training"))
>>> fig.savefig("training.png", dpi=120)
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle, FancyArrowPatch, Polygon
from matplotlib.ticker import MultipleLocator

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from sitframe.sim.world import World

__all__ = ["plot_world"]

_TRAJ_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:red", "tab:brown")


def plot_world(
    world: World,
    *,
    ax: Axes | None = None,
    show_trajectories: bool = True,
    show_start: bool = True,
    show_goal: bool = True,
    robot_radius: float = 0.15,
) -> Figure:
    """Draw ``world`` to scale and return the figure.

    Parameters
    ----------
    world
        The world to draw.
    ax
        Axes to draw into; a new figure sized to the world is made if None.
    show_trajectories
        Draw forced trajectories as dashed coloured lines with direction
        arrows and numbered legs (as in the thesis's data-collection figure).
    show_start
        Draw the robot at its start pose: a disc with a heading line.
    show_goal
        Draw the goal: a star marker and its radius circle.
    robot_radius
        Radius [m] of the drawn robot disc.

    Returns
    -------
    matplotlib.figure.Figure
        The figure containing the axes (1 m grid, equal aspect, "x [m]" /
        "y [m]" labels, world name as title).
    """
    x0, y0, x1, y1 = world.bounds
    own = ax is None  # lay out only a figure made here, never the caller's
    if ax is None:
        w, h = x1 - x0, y1 - y0
        scale = 7.0 / max(w, h)
        fig = Figure(figsize=(max(w * scale, 3.0) + 1.2, max(h * scale, 3.0) + 0.9))
        ax = fig.add_subplot(1, 1, 1)
    else:
        fig = ax.figure  # type: ignore[assignment]

    for poly in world.obstacles:
        ax.add_patch(Polygon(poly, closed=True, facecolor="0.7", edgecolor="0.25", lw=1.2,
                             zorder=2))
    for wall in world.walls:
        ax.plot(wall[:, 0], wall[:, 1], color="0.1", lw=2.2, solid_capstyle="round", zorder=3)

    if show_trajectories:
        for k, traj in enumerate(world.trajectories):
            colour = _TRAJ_COLOURS[k % len(_TRAJ_COLOURS)]
            ax.plot(traj[:, 0], traj[:, 1], ls="--", color=colour, lw=1.3, zorder=4)
            for i in range(traj.shape[0] - 1):
                a, b = traj[i], traj[i + 1]
                mid = a + 0.55 * (b - a)
                d = (b - a) / max(float(np.hypot(*(b - a))), 1e-12)
                ax.add_patch(FancyArrowPatch(mid - 0.12 * d, mid + 0.12 * d, arrowstyle="-|>",
                                             mutation_scale=11, color=colour, zorder=5))
                ax.annotate(str(i + 1), mid - 0.3 * d, fontsize=7, color=colour,
                            ha="center", va="center", zorder=5)

    if show_goal and world.goal is not None:
        gx, gy = world.goal.position
        ax.add_patch(Circle((gx, gy), world.goal.radius, facecolor="gold", alpha=0.35,
                            edgecolor="darkgoldenrod", zorder=3))
        ax.plot([gx], [gy], marker="*", ms=14, color="darkgoldenrod", zorder=6)

    if show_start:
        sx, sy, th = world.start
        ax.add_patch(Circle((sx, sy), robot_radius, facecolor="white", edgecolor="crimson",
                            lw=1.5, zorder=6))
        ax.plot([sx, sx + robot_radius * math.cos(th)], [sy, sy + robot_radius * math.sin(th)],
                color="crimson", lw=1.5, zorder=7)

    pad = 0.3
    ax.set_xlim(x0 - pad, x1 + pad)
    ax.set_ylim(y0 - pad, y1 + pad)
    ax.set_aspect("equal")
    ax.xaxis.set_major_locator(MultipleLocator(1.0))
    ax.yaxis.set_major_locator(MultipleLocator(1.0))
    ax.grid(True, color="0.88", lw=0.6, zorder=0)
    ax.set_axisbelow(True)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(world.name)
    if own:
        fig.tight_layout()
    return fig
