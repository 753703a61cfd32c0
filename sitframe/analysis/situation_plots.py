"""Figures of evolving situations (:mod:`sitframe.situations`): how many, where made.

Used by ``sitframe analyse`` when a log's trials carry a ``situations`` group.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from sitframe.sim.draw import plot_world
from sitframe.situations.events import KINDS, count_per_iteration

#: Marker and colour of each event kind on the room map.
_STYLE = {"create": ("o", "tab:blue"), "split": ("^", "tab:red"), "merge": ("s", "tab:green"),
          "prune": ("x", "tab:gray")}


def plot_situation_counts(counts: dict[int, np.ndarray], title: str) -> Figure:
    """Number of alive situations (y) against the iteration (x), one line per trial.

    ``counts`` maps a trial index to its (L,) count per iteration
    (:func:`sitframe.situations.events.count_per_iteration`).
    """
    fig = Figure(figsize=(7, 3.6), layout="constrained")  # (no pyplot: nothing to close)
    ax = fig.add_subplot()
    for k, c in sorted(counts.items()):
        ax.step(np.arange(c.size), c, where="post", lw=1.2, alpha=0.8, label=f"trial {k}")
    ax.set_xlabel("Iteration")
    ax.set_ylabel("Situations")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if len(counts) <= 12:
        ax.legend(fontsize=7, ncols=2, loc="lower right")
    return fig


def plot_event_map(world: Any, events: dict[int, dict[str, np.ndarray]], title: str,
                   robot_radius: float = 0.15) -> Figure:
    """Where in ``world`` the robot was when situations were created, split, merged or pruned
    (all trials; the events' logged ``pose``)."""
    fig = plot_world(world, show_trajectories=False, robot_radius=robot_radius)
    ax = fig.axes[0]
    for code, kind in enumerate(KINDS):
        xy = [ev["pose"][np.asarray(ev["kind"]) == code, :2] for ev in events.values()
              if np.asarray(ev.get("kind", [])).size]
        xy = np.concatenate(xy) if xy else np.zeros((0, 2))
        if xy.size:
            marker, colour = _STYLE[kind]
            ax.scatter(xy[:, 0], xy[:, 1], marker=marker, s=22, color=colour, alpha=0.7,
                       label=f"{kind} ({len(xy)})", zorder=5)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), framealpha=0.85)
    ax.set_title(title)
    fig.tight_layout()  # (again: room for the legend beside the map)
    return fig


def counts_of(trials: dict[int, Any], initial: int) -> dict[int, np.ndarray]:
    """Trial index -> (L,) situations alive after each iteration, from the logged events."""
    return {k: count_per_iteration(tr.situations_part("events"), initial,
                                   int(np.asarray(tr.arrays["collision"]).size))
            for k, tr in trials.items()}
