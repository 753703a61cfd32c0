"""Figures of the learning and evaluation stages (thesis Figs. 5.4-5.8, 5.10, 5.11).

Every function builds and returns a :class:`matplotlib.figure.Figure` without
pyplot (headless-safe; save with ``fig.savefig(path, dpi=200)``). Single-panel
figures are 3.5 in wide (one journal column), fonts 7-8 pt, colours from the
Okabe-Ito colour-blind-safe palette (:data:`OKABE_ITO`), sequential maps
``Blues`` / ``cividis`` (both readable in grey-scale and by colour-blind readers).

The functions take arrays (see :mod:`sitframe.analysis.results` for how to get
them from a log), so they also work on data that never went through a log.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, MultipleLocator

from sitframe.analysis.clustering_plots import OKABE_ITO
from sitframe.analysis.results import (
    CollisionIntervals,
    _deg,
    collision_points,
    episode_rows,
    reward_per_window,
)
from sitframe.sim.draw import plot_world
from sitframe.sim.world import World

__all__ = [
    "ITERATION_S",
    "plot_collision_intervals",
    "plot_evaluation_paths",
    "plot_exploration",
    "plot_learning_curves",
    "plot_reward_per_window",
    "plot_trajectory",
]

#: Seconds of robot time per iteration (thesis: a command is held 1.5 s).
ITERATION_S = 1.5
_FONT = 8
_COL = 3.5  # in, one column
_C = OKABE_ITO


def _path_cmap() -> ListedColormap:
    """cividis without its palest yellow end, so late path segments stay visible on white."""
    import matplotlib

    base = matplotlib.colormaps["cividis"]
    return ListedColormap(base(np.linspace(0.0, 0.82, 256)), name="cividis_dark")


def _panel(height: float, ylabel: str, title: str, *, zero: bool = True,
           xlabel: str = "Iteration (1 it. = 1.5 s)", ylabel_size: float = _FONT
           ) -> tuple[Figure, Any]:
    """A one-column figure over iterations: labels, title, y grid, (``zero``) a line at 0.

    Returns the figure and its axes.
    """
    fig = Figure(figsize=(_COL, height), layout="constrained")
    ax = fig.add_subplot()
    if zero:
        ax.axhline(0, color="0.4", lw=0.6)
    ax.set_xlabel(xlabel, fontsize=_FONT)
    ax.set_ylabel(ylabel, fontsize=ylabel_size)
    ax.set_title(title, fontsize=_FONT)
    ax.tick_params(labelsize=_FONT - 1)
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    ax.set_axisbelow(True)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    return fig, ax


def _by_window(curves: list[np.ndarray]) -> np.ndarray:
    """Curves of unequal length as rows of one (n, longest) array, padded with NaN."""
    M = np.full((len(curves), max(c.size for c in curves)), np.nan)
    for i, c in enumerate(curves):
        M[i, :c.size] = c
    return M


def _mark_convergence(ax, convergence: int | None, n_iterations: int | None = None) -> None:
    """Vertical dashed line labelled at the top at the convergence iteration, or a note."""
    if convergence is not None:
        ax.axvline(convergence, color=_C["vermillion"], lw=1.0, ls="--", zorder=1)
        right = n_iterations is not None and convergence > 0.7 * n_iterations
        ax.annotate(f"converged\nit. {convergence}", (convergence, 1.0),
                    xycoords=("data", "axes fraction"), xytext=(-3 if right else 3, -2),
                    textcoords="offset points", ha="right" if right else "left", va="top",
                    fontsize=_FONT - 1.5, color=_C["vermillion"],
                    bbox={"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none",
                          "alpha": 0.8})
    else:
        txt = "not converged" + (f" in {n_iterations} it." if n_iterations else "")
        ax.text(0.99, 0.98, txt, transform=ax.transAxes, ha="right", va="top",
                fontsize=_FONT - 1, color=_C["vermillion"],
                bbox={"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.8})


# ----------------------------------------------------------------------- exploration


def plot_exploration(
    counts: np.ndarray,
    situation_labels: Sequence[str] | None = None,
    actions: Sequence[float] | None = None,
    *,
    title: str | None = None,
    action_unit: str = "deg",
) -> Figure:
    """Exploration distribution of situation-action pairs as an annotated heat map (Fig. 5.4).

    Parameters
    ----------
    counts : array_like of int, shape (c, A)
        ``counts[s, a]`` = iterations in which situation ``s`` was dominant and
        executed action ``a`` (:func:`sitframe.analysis.results.exploration_counts`).
    situation_labels : sequence of str, optional
        One label per situation (row); default ``S1 ... Sc``.
    actions : sequence of float, optional
        Action values (columns), e.g. heading changes in degrees.
    title : str, optional
        Figure title; default states the number of iterations.
    action_unit : str
        ``"deg"`` formats actions as signed degrees.

    Returns
    -------
    matplotlib.figure.Figure
    """
    N = np.asarray(counts)
    if N.ndim != 2:
        raise ValueError(f"counts must be (situations, actions), got shape {N.shape}")
    c, A = N.shape
    ylab = list(situation_labels) if situation_labels is not None else [
        f"S{i + 1}" for i in range(c)]
    if len(ylab) != c:
        raise ValueError(f"need {c} situation labels, got {len(ylab)}")
    if actions is None:
        xlab = [f"A{j + 1}" for j in range(A)]
    else:
        xlab = [_deg(float(a)) if action_unit == "deg" else f"{a:g}" for a in actions]
    annotate = c * A <= 200
    width = max(_COL, 1.0 + 0.3 * A + 0.052 * max(len(s) for s in ylab)
                + (0 if annotate else 0.7))
    fig = Figure(figsize=(width, 0.26 * c + 1.0), layout="constrained")
    ax = fig.add_subplot()
    vmax = max(int(N.max()), 1)
    im = ax.imshow(N, cmap="Blues", vmin=0, vmax=vmax, aspect="auto")
    if annotate:  # the numbers are the data; no colour bar needed
        for (i, j), v in np.ndenumerate(N):
            ax.text(j, i, str(int(v)), ha="center", va="center", fontsize=_FONT - 2,
                    color="white" if v > 0.55 * vmax else "black")
    else:
        cb = fig.colorbar(im, ax=ax, shrink=0.9, pad=0.02)
        cb.set_label("Iterations", fontsize=_FONT)
        cb.ax.tick_params(labelsize=_FONT - 1)
    ax.set_xticks(range(A), xlab)
    ax.set_yticks(range(c), ylab)
    ax.tick_params(labelsize=_FONT - 1, length=0)
    ax.set_xlabel("Executed action" + (" (heading change)" if action_unit == "deg" else ""),
                  fontsize=_FONT)
    ax.set_ylabel("Dominant situation", fontsize=_FONT)
    ax.set_xticks(np.arange(-0.5, A), minor=True)
    ax.set_yticks(np.arange(-0.5, c), minor=True)
    ax.grid(which="minor", color="white", lw=0.8)
    ax.tick_params(which="minor", length=0)
    for sp in ax.spines.values():
        sp.set_visible(False)
    ax.set_title(title or f"Situation-action pairs over {int(N.sum())} iterations",
                 fontsize=_FONT)
    return fig


# ------------------------------------------------------------------------ collisions


def plot_collision_intervals(
    intervals: CollisionIntervals,
    convergence: int | None = None,
    *,
    title: str | None = None,
    log_scale: bool | None = None,
) -> Figure:
    """Iterations between successive collisions over the run (Figs. 5.5, 5.6).

    Each collision is a stem at the iteration it happened, as tall as the
    number of iterations since the previous collision; the right axis gives
    the same in minutes of robot time (1 iteration = 1.5 s). A dotted stem with
    a hollow marker at the end of the run shows the collision-free stretch
    after the last collision (a lower bound on the next interval).

    Parameters
    ----------
    intervals : CollisionIntervals
        From :func:`sitframe.analysis.results.collision_intervals`.
    convergence : int, optional
        Convergence iteration (dashed line); None notes "not converged".
    title : str, optional
    log_scale : bool, optional
        Logarithmic y axis; default when the intervals span more than 2 decades.

    Returns
    -------
    matplotlib.figure.Figure
    """
    it, iv = intervals.iterations, intervals.intervals
    L = intervals.n_iterations
    tail = L - (int(it[-1]) + 1 if it.size else 0)  # collision-free iterations at the end
    fig, ax = _panel(2.4, "Iterations since previous collision",
                     title or f"{it.size} collisions in {L} iterations", zero=False,
                     xlabel="Iteration of the collision (1 it. = 1.5 s)",
                     ylabel_size=_FONT - 0.5)
    top = max(int(iv.max()) if iv.size else 1, tail, 1)
    if log_scale is None:
        log_scale = bool(iv.size) and top / max(int(iv.min()), 1) > 100
    base = 0.8 if log_scale else 0
    if it.size:
        ax.vlines(it, base, iv, color=_C["blue"], lw=0.6)
        ax.plot(it, iv, "o", ms=1.8, color=_C["blue"])
    else:
        ax.text(0.5, 0.5, "no collisions", transform=ax.transAxes, ha="center",
                fontsize=_FONT)
    if tail > 0 and it.size:
        ax.vlines([L], base, [tail], color=_C["blue"], lw=0.6, ls=":")
        ax.plot([L], [tail], "o", ms=3, mfc="white", color=_C["blue"], clip_on=False, zorder=4)
        ax.annotate(f"{tail} it. collision-free\nto the end", (L, tail), xytext=(-4, 0),
                    textcoords="offset points", ha="right", va="center",
                    fontsize=_FONT - 1.5, color=_C["blue"])
    if log_scale:  # (before the secondary axis is made, which follows the scale it sees)
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _p: f"{v:g}"))
    ax.set_ylim(*((base, top * 2.0) if log_scale else (0, top * 1.12 + 1)))
    ax.set_xlim(0, max(L, 1) * 1.02)
    _mark_convergence(ax, convergence, L)
    sec = ax.secondary_yaxis("right", functions=(lambda x: x * ITERATION_S / 60.0,
                                                 lambda m: m * 60.0 / ITERATION_S))
    sec.set_ylabel("Minutes of robot time", fontsize=_FONT - 0.5)
    sec.tick_params(labelsize=_FONT - 1)
    if log_scale:
        sec.set_yscale("log")
        sec.yaxis.set_major_formatter(FuncFormatter(lambda v, _p: f"{v:g}"))
    ax.spines["right"].set_visible(True)
    return fig


# --------------------------------------------------------------------------- rewards


def plot_reward_per_window(
    reward: np.ndarray,
    window: int = 50,
    convergence: int | None = None,
    *,
    title: str | None = None,
    reward_label: str = "Mean reward",
) -> Figure:
    """Mean reward per window of iterations over the run (Figs. 5.7, 5.8).

    Parameters
    ----------
    reward : array_like, shape (L,)
        Per-iteration reward of one reward plugin.
    window : int, default 50
        Iterations per window.
    convergence : int, optional
        Convergence iteration (dashed line).
    title, reward_label : str

    Returns
    -------
    matplotlib.figure.Figure
    """
    r = np.asarray(reward, dtype=np.float64)
    means = reward_per_window(r, window)
    x = np.arange(means.size) * window
    fig, ax = _panel(2.3, f"{reward_label} per {window} it.",
                     title or f"Mean reward per {window} iterations")
    ax.bar(x, means, width=window, align="edge", color=np.where(
        means >= 0, _C["sky_blue"], _C["orange"]), edgecolor="white", lw=0.2)
    ax.step(np.r_[x, r.size], np.r_[means, means[-1:]], where="post", color=_C["blue"], lw=0.7)
    ax.set_xlim(0, max(r.size, 1))
    _mark_convergence(ax, convergence, r.size)
    return fig


def plot_learning_curves(
    rewards: Mapping[int, np.ndarray],
    convergence: Mapping[int, int | None] | None = None,
    window: int = 50,
    *,
    title: str | None = None,
) -> Figure:
    """Mean reward per window of every trial, and their mean (all trials of a run).

    Parameters
    ----------
    rewards : mapping trial -> array (L,)
        Per-iteration reward of each trial.
    convergence : mapping trial -> int or None, optional
        Convergence iteration of each trial (a dot on its curve).
    window : int, default 50
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    convergence = convergence or {}
    fig, ax = _panel(2.4, f"Mean reward per {window} it.",
                     title or "Learning curves of all trials")
    curves = {k: reward_per_window(v, window) for k, v in rewards.items()}
    n = max((c.size for c in curves.values()), default=0)
    for k, c in curves.items():
        x = (np.arange(c.size) + 0.5) * window
        ax.plot(x, c, color="0.6", lw=0.6, alpha=0.8)
        conv = convergence.get(k)
        if conv is not None and conv // window < c.size:
            ax.plot([x[conv // window]], [c[conv // window]], "o", ms=3.5,
                    color=_C["vermillion"], zorder=4)
    if curves:
        ax.plot((np.arange(n) + 0.5) * window, np.nanmean(_by_window(list(curves.values())),
                                                          axis=0), color=_C["blue"], lw=1.6)
    handles = [Line2D([], [], color="0.6", lw=0.8, label="one trial"),
               Line2D([], [], color=_C["blue"], lw=1.6, label=f"mean of {len(curves)} trials")]
    if any(v is not None for v in convergence.values()):
        handles.append(Line2D([], [], ls="", marker="o", ms=3.5, color=_C["vermillion"],
                              label="convergence"))
    fig.legend(handles=handles, fontsize=_FONT - 1, loc="outside lower center",
               ncols=len(handles), frameon=False)
    ax.set_xlim(0, max(n * window, 1))
    return fig


# ---------------------------------------------------------------------- trajectories


def _draw_path(ax, world: World, pose: np.ndarray, collision: np.ndarray | None,
               contact: np.ndarray | None, start: int, stop: int, radius: float,
               first: np.ndarray | None = None, goals: np.ndarray | None = None):
    """Draw the world and the path of iterations [start, stop); return the LineCollection
    and the number of collisions drawn.

    ``first``: the first iteration of each episode, when the path is a chain of
    episodes (goal episodes). A learning trial's chain has one pose row per
    iteration and one more, the next episode's start replacing the last step's
    end; an evaluation batch has one more row per episode (each episode's end).
    Either way the jump from one episode to the next is not drawn, and each
    drawn episode's goal (``goals``, (episodes, >= 2) [m]) is starred instead
    of the world's ``[goal]``.
    """
    plot_world(world, ax=ax, show_trajectories=False, show_start=False,
               show_goal=goals is None, robot_radius=radius)
    P = np.asarray(pose)
    it = np.arange(start, stop)
    row = it.copy()  # the pose row each iteration starts from
    if first is not None:
        f = np.asarray(first, dtype=np.intp)
        n_it = P.shape[0] - 1 if collision is None else len(collision)
        row = episode_rows(n_it, f, P.shape[0])[0][start:stop]
        if P.shape[0] == n_it + 1:  # (a learning chain: iteration first[j] - 1 ends where
            keep = ~np.isin(it, f[f > 0] - 1)  # episode j starts: not drawn)
            it, row = it[keep], row[keep]
        if goals is not None:
            g = np.asarray(goals, dtype=float)[:len(f), :2]
            ends = np.append(f[1:], np.iinfo(np.intp).max)[:len(g)]
            shown = g[(f[:len(g)] < stop) & (ends > start)]
            ax.plot(shown[:, 0], shown[:, 1], ls="", marker="*", ms=7, color="darkgoldenrod",
                    zorder=6)
    seg = np.stack([P[row, :2], P[row + 1, :2]], axis=1)
    lc = LineCollection(seg, cmap=_path_cmap(), lw=0.9, zorder=5)
    lc.set_array(it)
    lc.set_clim(start, max(stop, start + 1))
    ax.add_collection(lc)
    if len(row):
        ax.plot(*P[row[0], :2], "o", ms=4.5, mfc="white", mec="black", mew=1.0, zorder=7)
        ax.plot(*P[row[-1] + 1, :2], "s", ms=4.5, mfc="black", mec="black", zorder=7)
    hit = np.zeros(0, bool) if collision is None else np.asarray(collision, dtype=bool)[it]
    if hit.any():
        pts = collision_points(P, it[hit], contact, rows=row[hit])
        ax.plot(pts[:, 0], pts[:, 1], "x", ms=4, mew=1.1, color=_C["vermillion"], zorder=8)
    x0, y0, x1, y1 = world.bounds
    if max(x1 - x0, y1 - y0) > 8:  # 1 m ticks crowd a column-wide panel; grid stays at 1 m
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_locator(MultipleLocator(2.0))
            axis.set_minor_locator(MultipleLocator(1.0))
        ax.grid(True, which="minor", color="0.88", lw=0.6, zorder=0)
    for t in ax.texts:
        t.set_fontsize(_FONT - 2)
    ax.tick_params(labelsize=_FONT - 1)
    ax.xaxis.label.set_fontsize(_FONT)
    ax.yaxis.label.set_fontsize(_FONT)
    return lc, int(hit.sum())


def _path_keys(fig: Figure, lc: LineCollection, ax: Any, collisions: bool,
               goals: bool = False, **colorbar: Any) -> None:
    """The colour bar (iteration) beside ``ax`` and the legend (start, end, collisions) below."""
    fig.set_layout_engine("constrained")
    cb = fig.colorbar(lc, ax=ax, **colorbar)
    cb.set_label("Iteration", fontsize=_FONT)
    cb.ax.tick_params(labelsize=_FONT - 1)
    handles = [Line2D([], [], ls="", marker="o", ms=4.5, mfc="white", mec="black", label="start"),
               Line2D([], [], ls="", marker="s", ms=4.5, color="black", label="end")]
    if collisions:
        handles.append(Line2D([], [], ls="", marker="x", ms=4, mew=1.1, color=_C["vermillion"],
                              label="collision"))
    if goals:
        handles.append(Line2D([], [], ls="", marker="*", ms=7, color="darkgoldenrod",
                              label="episode goal"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles),
               fontsize=_FONT - 1, frameon=False)


def _window(n: int, start: int | None, stop: int | None) -> tuple[int, int]:
    s = 0 if start is None else max(0, min(int(start), n - 1 if n else 0))
    e = n if stop is None else max(s + 1, min(int(stop), n))
    return s, e


def plot_trajectory(
    world: World,
    pose: np.ndarray,
    *,
    collision: np.ndarray | None = None,
    contact: np.ndarray | None = None,
    start: int | None = None,
    stop: int | None = None,
    robot_radius: float = 0.15,
    title: str | None = None,
    first: np.ndarray | None = None,
    goals: np.ndarray | None = None,
) -> Figure:
    """The robot's path on the world, coloured by iteration, collisions marked (Figs. 5.10/5.11).

    Parameters
    ----------
    world : World
        The world the path was driven in.
    pose : array_like, shape (L+1, 3)
        Poses [m, m, rad]; row ``i`` is the pose at the start of iteration ``i``.
    collision : array_like of bool, shape (L,), optional
        Collision flags; marked with a cross.
    contact : array_like, shape (L, 2), optional
        Contact points [m]; without them a collision is marked at the pose
        after the colliding iteration.
    start, stop : int, optional
        Iteration window ``[start, stop)``; default the whole path.
    robot_radius : float
        For the world drawing, metres.
    title : str, optional
    first, goals : array_like, optional
        A chain of episodes (a learning trial run in goal episodes): the first
        iteration of each, and its goal (episodes, >= 2) [m]; the jumps between
        episodes are not drawn and the drawn episodes' goals are starred.

    Returns
    -------
    matplotlib.figure.Figure
        One panel, 3.5 in wide (wider for tall worlds), colour bar = iteration.
    """
    P = np.asarray(pose)
    n = P.shape[0] - 1 if collision is None else len(collision)
    s, e = _window(n, start, stop)
    x0, y0, x1, y1 = world.bounds
    aspect = (y1 - y0 + 0.6) / (x1 - x0 + 0.6)
    fig = Figure(figsize=(_COL, min((_COL - 1.25) * aspect + 1.05, 5.5)))
    ax = fig.add_subplot()
    lc, n_coll = _draw_path(ax, world, P, collision, contact, s, e, robot_radius, first, goals)
    _path_keys(fig, lc, ax, collision is not None, first is not None and goals is not None,
               shrink=0.95, pad=0.02, aspect=25)
    ax.set_title(title or f"{world.name}: it. {s}–{e}, {n_coll} collisions", fontsize=_FONT)
    return fig


def plot_evaluation_paths(
    worlds: Mapping[str, World],
    episodes: Mapping[str, Mapping[str, np.ndarray]],
    *,
    start: int | None = None,
    stop: int | None = None,
    robot_radius: float = 0.15,
    coverage: Mapping[str, float] | None = None,
    title: str | None = None,
    ncols: int | None = None,
) -> Figure:
    """Evaluation paths of a frozen rule base, one panel per world (Figs. 5.10, 5.11, A.5).

    Parameters
    ----------
    worlds : mapping name -> World
    episodes : mapping name -> {"pose": (n+1, 3), "collision": (n,)}
        As returned by :func:`sitframe.analysis.results.evaluation_episodes`;
        a batch of goal episodes (``first_iteration``, ``goal``) is drawn
        episode by episode, each with its goal starred.
    start, stop : int, optional
        Iteration window drawn in every panel (collisions counted in it).
    robot_radius : float
    coverage : mapping name -> float, optional
        Coverage of each whole episode, printed in the panel title.
    title : str, optional
    ncols : int, optional
        Panels per row (default up to 3).

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = [w for w in episodes if w in worlds]
    if not names:
        raise ValueError("no episode has a matching world")
    ncols = ncols or min(3, len(names))
    nrows = math.ceil(len(names) / ncols)
    fig = Figure(figsize=(2.45 * ncols + 0.5, 2.35 * nrows + 0.55))
    for k, name in enumerate(names):
        ax = fig.add_subplot(nrows, ncols, k + 1)
        ep = episodes[name]
        n = len(ep["collision"]) if "collision" in ep else np.asarray(ep["pose"]).shape[0] - 1
        s, e = _window(n, start, stop)
        lc, n_coll = _draw_path(ax, worlds[name], ep["pose"], ep.get("collision"),
                                ep.get("contact"), s, e, robot_radius,
                                ep.get("first_iteration"), ep.get("goal"))
        cov = "" if not coverage or name not in coverage else (
            f", coverage {coverage[name]:.2f}")
        ax.set_title(f"{name}: it. {s}–{e}, {n_coll} coll.{cov}", fontsize=_FONT - 1)
    _path_keys(fig, lc, fig.axes, True,
               any("first_iteration" in e and "goal" in e for e in episodes.values()),
               shrink=0.7, pad=0.01, aspect=30)
    if title:
        fig.suptitle(title, fontsize=_FONT + 1)
    return fig
