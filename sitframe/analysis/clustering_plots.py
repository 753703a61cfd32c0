"""Figures of the clustering stage: prototypes (thesis Fig. 5.2), validity per trial (Fig. 5.1)
and per number of clusters (Fig. 4.5).

Every function builds and returns a :class:`matplotlib.figure.Figure` without
touching pyplot's global state (headless-safe; save it with ``fig.savefig``).
Colours are from the Okabe-Ito colour-blind-safe palette.
"""

from __future__ import annotations

import math
import textwrap
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from sitframe.situations.clustering import ClusteringTrials, SweepResult
from sitframe.situations.fcm import MEASURE_DIRECTIONS
from sitframe.situations.labels import describe_prototypes

__all__ = ["OKABE_ITO", "plot_auto_c", "plot_measures_by_c", "plot_measures_by_trial",
           "plot_prototypes"]

#: Okabe-Ito palette (colour-blind safe).
OKABE_ITO: dict[str, str] = {
    "black": "#000000",
    "orange": "#E69F00",
    "sky_blue": "#56B4E9",
    "bluish_green": "#009E73",
    "yellow": "#F0E442",
    "blue": "#0072B2",
    "vermillion": "#D55E00",
    "reddish_purple": "#CC79A7",
}

# short panel titles and y-axis labels (units: X in metres -> J_m in m^2)
_TITLES = {
    "pc": "Partition coefficient",
    "pe": "Partition entropy",
    "nfi": "Non-fuzzy index",
    "min_ht": "Min. hard tend.",
    "mean_ht": "Mean hard tend.",
    "min_card": "Min. cardinality",
    "rf": "Relative fuzziness",
    "objective": "Objective $J_m$",
}
_YLABELS = {
    "pc": "$V_{PC}$",
    "pe": "$V_{PE}$ (nats)",
    "nfi": "NFI",
    "min_ht": "MinHT",
    "mean_ht": "MeanHT",
    "min_card": "MinCard (samples)",
    "rf": "$R_f$",
    "objective": "$J_m$ ({u}$^2$)",
}
_DIRECTION_WORDS = {"max": "max", "min": "min", "positive": "> 0"}
_FONT = 8


def _panel_title(key: str) -> str:
    return f"{_TITLES[key]} ({_DIRECTION_WORDS[MEASURE_DIRECTIONS[key]]})"


def plot_prototypes(
    centers: np.ndarray,
    angles_deg: np.ndarray,
    *,
    max_range: float = 3.0,
    labels: list[str] | None = None,
    ncols: int | None = None,
    first_index: int = 1,
) -> Figure:
    """Each cluster prototype as a polar plot of its ranges, one per beam (thesis Fig. 5.2).

    Front is up and left is left (bearings counter-clockwise from the heading);
    each beam is drawn from the robot (the black triangle at the centre, pointing
    along the heading) to its range, the free space they enclose is shaded. Any
    beam layout: a front arc (all ``|bearing| <= 100`` deg, e.g. the Pioneer
    ring or a 180 deg laser) gets the front half-disc, anything wider the full
    circle, with gridlines every 45 deg.

    Parameters
    ----------
    centers : array_like, shape (c, d)
        Prototypes: one range per beam, metres (clipped to ``max_range`` for drawing).
    angles_deg : array_like, shape (d,)
        Beam bearings, degrees, positive = left (the sensor's ``SensorSpec.angles_deg``).
    max_range : float, metres
        The sensor's maximum range = radial axis limit.
    labels : list of str, optional
        One description per prototype; default
        :func:`~sitframe.situations.labels.describe_prototypes` (no two alike).
    ncols : int, optional
        Columns of the grid (default ``min(c, 4)``).
    first_index : int, default 1
        Number of the first situation (as in the thesis) in the titles ``"S{i}: {label}"``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    V = np.asarray(centers, dtype=np.float64)
    a = np.asarray(angles_deg, dtype=np.float64)
    if V.ndim != 2 or a.ndim != 1 or V.shape[1] != a.size:
        raise ValueError(f"centers must be (c, d) and angles_deg (d,) with the same d, got "
                         f"shapes {V.shape} and {a.shape}")
    if not max_range > 0:
        raise ValueError(f"max_range must be > 0 (metres), got {max_range}")
    c = V.shape[0]
    if labels is None:
        labels = describe_prototypes(V, a)
    elif len(labels) != c:
        raise ValueError(f"labels must have one entry per prototype ({c}), got {len(labels)}")
    ncols = min(c, 4) if ncols is None else int(ncols)
    if ncols < 1:
        raise ValueError(f"ncols must be >= 1, got {ncols}")
    nrows = math.ceil(c / ncols)
    a = (a + 180.0) % 360.0 - 180.0  # [-180, 180)
    order = np.argsort(a)
    th = np.deg2rad(a[order])
    ring = bool(np.any(np.abs(a) > 100))  # beyond the front half-disc: draw the full circle
    fig = Figure(figsize=(1.75 * ncols + 0.2, (2.0 if ring else 1.45) * nrows + 0.35),
                 layout="constrained")
    ticks = np.arange(1.0, max_range + 1e-9, 1.0)
    for i in range(c):
        ax = fig.add_subplot(nrows, ncols, i + 1, projection="polar")
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(1)  # counter-clockwise: positive bearings to the left
        ax.set_thetamin(-180 if ring else -100)
        ax.set_thetamax(180 if ring else 100)
        ax.set_ylim(0, max_range)
        r = np.clip(V[i, order], 0.0, max_range)
        # the free space: a fan from the robot, or (a ring) the polygon closed behind it
        ft, fr = (np.r_[th, th[0] + 2 * np.pi], np.r_[r, r[0]]) if ring else \
            (np.r_[0.0, th, 0.0], np.r_[0.0, r, 0.0])
        ax.fill(ft, fr, color=OKABE_ITO["sky_blue"], alpha=0.35, lw=0)
        for t, rr in zip(th, r, strict=True):
            ax.plot([t, t], [0, rr], color=OKABE_ITO["blue"], lw=0.9)
        ax.plot(th, r, "o", color=OKABE_ITO["blue"], ms=3, zorder=3)
        ax.plot([0], [0], marker="^", color=OKABE_ITO["black"], ms=6, zorder=4)
        ax.set_xticks(np.deg2rad(np.arange(-135, 181, 45) if ring else [-90, -45, 0, 45, 90]))
        ax.set_xticklabels([])
        ax.set_yticks(ticks)
        ax.set_yticklabels([f"{t:g}" for t in ticks[:-1]] + [f"{ticks[-1]:g} m"])
        ax.tick_params(axis="y", labelsize=_FONT - 2, pad=0)
        ax.set_rlabel_position(-146 if ring else -97)
        ax.grid(lw=0.4, alpha=0.6)
        ax.set_title("\n".join(textwrap.wrap(f"S{i + first_index}: {labels[i]}", 26)),
                     fontsize=_FONT, pad=2)
    fig.suptitle("Cluster prototypes: range per beam (m), front up, left on the left",
                 fontsize=_FONT + 1)
    return fig


def _plot_measures(measures: dict[str, np.ndarray], draw: Any, xlabel: str, units: str,
                   title: str, legend: bool = True) -> Figure:
    """One panel per validity measure, four per row; ``draw(ax, values)`` plots a measure
    (non-finite values as NaN, counted in a note), then the panel gets its title, labels,
    grid and, for MinCard, the zero line."""
    keys = list(MEASURE_DIRECTIONS)
    fig = Figure(figsize=(7.2, 1.8 * math.ceil(len(keys) / 4) + 0.4), layout="constrained")
    axes = fig.subplots(math.ceil(len(keys) / 4), 4, squeeze=False).ravel()
    for ax in axes[len(keys):]:
        ax.set_visible(False)
    for ax, key in zip(axes, keys, strict=False):
        v = np.asarray(measures[key], dtype=np.float64)
        n_bad = int((~np.isfinite(v)).sum())
        draw(ax, np.where(np.isfinite(v), v, np.nan))
        if key == "min_card":
            ax.axhline(0, color=OKABE_ITO["black"], lw=0.6, ls="--")
        ax.set_title(_panel_title(key), fontsize=_FONT - 0.5)
        ax.set_ylabel(_YLABELS[key].replace("{u}", units), fontsize=_FONT)
        ax.set_xlabel(xlabel, fontsize=_FONT)
        ax.tick_params(labelsize=_FONT - 1)
        ax.grid(lw=0.3, alpha=0.5)
        if n_bad:
            ax.text(0.98, 0.04, f"{n_bad} infinite, not shown", transform=ax.transAxes,
                    ha="right", va="bottom", fontsize=_FONT - 2, color=OKABE_ITO["black"])
    if legend:
        handles, lbls = axes[0].get_legend_handles_labels()
        fig.legend(handles, lbls, loc="outside lower center", ncols=len(lbls), fontsize=_FONT,
                   frameon=False)
    fig.suptitle(title, fontsize=_FONT + 1)
    return fig


def plot_measures_by_trial(trials: ClusteringTrials, *, units: str = "m") -> Figure:
    """Every validity measure against trial index, chosen trial highlighted (thesis Fig. 5.1).

    Hollow markers are trials excluded from the selection (``min_card = 0``);
    each panel's title gives the measure's direction.

    Parameters
    ----------
    trials : ClusteringTrials
        Output of :func:`sitframe.situations.clustering.cluster_trials`.
    units : str, default "m"
        Units of the clustered data (for ``J_m``'s axis label).

    Returns
    -------
    matplotlib.figure.Figure
    """
    idx = np.arange(trials.n_trials)
    ok = trials.eligible
    k = trials.chosen

    def draw(ax: Axes, v: np.ndarray) -> None:
        ax.plot(idx, v, color=OKABE_ITO["blue"], lw=0.6, alpha=0.5)
        ax.plot(idx[ok], v[ok], "o", ms=2.8, color=OKABE_ITO["blue"], label="trial")
        if (~ok).any():
            ax.plot(idx[~ok], v[~ok], "o", ms=2.8, mfc="none", color=OKABE_ITO["blue"],
                    label="excluded (MinCard = 0)")
        ax.axvline(k, color=OKABE_ITO["vermillion"], lw=0.8, alpha=0.6, zorder=0)
        ax.plot([k], [v[k]], "D", ms=5, color=OKABE_ITO["vermillion"],
                label=f"chosen (trial {k})", zorder=4)

    return _plot_measures(trials.measures, draw, "Trial index", units,
                          f"Validity measures of {trials.n_trials} FCM trials "
                          f"(c = {trials.c}, m = {trials.m:g})")


def plot_measures_by_c(sweep: SweepResult, *, units: str = "m") -> Figure:
    """Validity measures of the chosen partition against the number of clusters (Fig. 4.5).

    ``sweep`` is the output of :func:`sitframe.situations.clustering.sweep_c`; ``units`` and
    the returned figure are as in :func:`plot_measures_by_trial`. Hollow markers mark numbers
    of clusters where no trial had ``min_card > 0``.
    """
    order = np.argsort(sweep.cs)
    cs = sweep.cs[order]
    fb = sweep.fallback[order]

    def draw(ax: Axes, v: np.ndarray) -> None:
        ax.plot(cs, v, "-", color=OKABE_ITO["bluish_green"], lw=1.0)
        ax.plot(cs[~fb], v[~fb], "o", ms=3, color=OKABE_ITO["bluish_green"],
                label="chosen trial")
        if fb.any():
            ax.plot(cs[fb], v[fb], "o", ms=3, mfc="none", color=OKABE_ITO["vermillion"],
                    label="no trial with MinCard > 0")
        if cs.size <= 20:
            ax.set_xticks(cs[:: max(1, math.ceil(cs.size / 7))])

    return _plot_measures({k: v[order] for k, v in sweep.measures.items()}, draw,
                          "Number of clusters $c$", units,
                          f"Validity of the chosen partition vs. number of clusters "
                          f"(m = {sweep.m:g}, {sweep.n_trials} trials per c)",
                          legend=bool(fb.any()))


def plot_auto_c(cs: np.ndarray, min_card: np.ndarray, rf: np.ndarray, chosen: int, *,
                plateau: float | None = None, knee: float | None = None,
                rule: str = "cardinality") -> Figure:
    """How ``c = "auto"`` chose c: the sweep's minimum cardinality and R_f against c.

    Parameters
    ----------
    cs : ndarray, shape (k,)
        The candidate numbers of situations.
    min_card, rf : ndarray, shape (k,)
        Minimum cardinality (readings of the smallest situation, Eq. 4.8) and relative
        fuzziness (Eq. 4.9) of each candidate's chosen partition.
    chosen : int
        The c the rule took (marked).
    plateau, knee : float, optional
        The ``"cardinality"`` rule's plateau and factor: the band up to ``knee *
        plateau`` is shaded.
    rule : str
        ``"cardinality"`` or ``"rf"``: the panel the rule read comes first.

    Returns
    -------
    matplotlib.figure.Figure
    """
    order = np.argsort(cs)
    cs, panels = np.asarray(cs)[order], {
        "cardinality": (np.asarray(min_card, float)[order],
                        "Minimum cardinality\n(readings of the smallest situation)"),
        "rf": (np.asarray(rf, float)[order], "Relative fuzziness $R_f$")}
    keys = ["cardinality", "rf"] if rule == "cardinality" else ["rf", "cardinality"]
    fig = Figure(figsize=(7.2, 2.6), layout="constrained")
    for ax, key in zip(fig.subplots(1, 2), keys, strict=True):
        v, label = panels[key]
        v = np.where(np.isfinite(v), v, np.nan)
        ax.plot(cs, v, "o-", ms=3, lw=1.0, color=OKABE_ITO["bluish_green"])
        at = np.flatnonzero(cs == chosen)
        if at.size:
            ax.plot(cs[at], v[at], "o", ms=8, mfc="none", mew=1.5,
                    color=OKABE_ITO["vermillion"], label=f"chosen c = {chosen}")
        if key == "cardinality" and plateau is not None and knee is not None and plateau > 0:
            ax.axhspan(0, knee * plateau, color=OKABE_ITO["sky_blue"], alpha=0.25, lw=0,
                       label=f"plateau band (<= {knee:g} x {plateau:g})")
            ax.set_ylim(bottom=0)
        ax.set_xlabel("Number of situations $c$", fontsize=_FONT)
        ax.set_ylabel(label, fontsize=_FONT)
        ax.set_xticks(cs[:: max(1, math.ceil(cs.size / 10))])
        ax.tick_params(labelsize=_FONT - 1)
        ax.grid(lw=0.3, alpha=0.5)
        ax.legend(fontsize=_FONT - 1, frameon=False)
    fig.suptitle(f'c = "auto" (rule "{rule}"): the sweep it chose c from', fontsize=_FONT + 1)
    return fig
