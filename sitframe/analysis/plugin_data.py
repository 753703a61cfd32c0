"""What the plugins logged, for the report: per plugin, an inventory, a table and figures.

A plugin's per-trial data is logged under ``/trials/NNNN/plugins/<plugin>/`` (what its
components return from ``trial_end`` and its observers from ``sitframe_trial_data``) and a
behaviour's under ``/trials/NNNN/behaviours/<label>/`` (what ``trial_data`` returns, beside
the learned policy the core logs there). ``sitframe analyse`` gives each such owner a
section (:func:`owners`):

* **what it logged** (:func:`inventory`): every key, whether it is a scalar, a
  per-iteration series (an array with a row per iteration of the trial, or of the
  evaluation its key is under, ``eval/<world>/...``) or another array, its shape and type
  and how many trials hold it;
* **its per-trial scalars** (:func:`scalar_table`): a row per trial, a column per
  scalar (numbers, bools and text);
* **a figure per per-iteration series** (:func:`plot_series`): every trial's series
  against the iteration (a 2-D series with more than :data:`MAX_LINES` columns: a map of
  the first trial shown).

The summary-table columns of the same scalars (``plugins.<plugin>.<key>``,
``behaviours.<label>.<key>``) are :meth:`sitframe.logs.reader.Log.plugin_scalars`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from sitframe.analysis.results import Table
from sitframe.logs.frames import POLICY_KEYS, is_series
from sitframe.logs.reader import Log, TrialLog

__all__ = ["MAX_LINES", "Owner", "inventory", "owners", "plot_series", "scalar_table",
           "series"]

#: A 2-D series with at most this many columns is drawn as lines, a wider one as a map.
MAX_LINES = 8


@dataclass(frozen=True)
class Owner:
    """Who logged a group of per-trial data: a plugin, or a behaviour (by its label).

    Attributes
    ----------
    kind : str
        ``"plugins"`` or ``"behaviours"`` (the group of the trial it is logged in).
    name : str
        The plugin's name, or the behaviour's label (``arbiter``: a learning arbiter).
    component : str
        A behaviour's component name (from the config), else ``""``.
    """

    kind: str
    name: str
    component: str = ""

    @property
    def title(self) -> str:
        """The report section's title."""
        if self.kind == "plugins":
            return f"Plugin '{self.name}': what it logged"
        what = f" ({self.component})" if self.component else ""
        return f"Behaviour '{self.name}'{what}: what it logged"

    def data(self, tr: TrialLog) -> dict[str, Any]:
        """What it logged in trial ``tr`` (a behaviour's learned policy left out)."""
        if self.kind == "plugins":
            return dict(tr.plugins.get(self.name, {}))
        return {k: v for k, v in tr.behaviours.get(self.name, {}).items()
                if not k.startswith(POLICY_KEYS)}


def owners(log: Log, trials: dict[int, TrialLog]) -> list[Owner]:
    """Every plugin and behaviour that logged something in ``trials``, plugins first."""
    try:
        cfg = log.config
    except Exception:  # noqa: BLE001 - a damaged config only loses the component names
        cfg = {}
    comps = {label: str(t.get("component", "")) for label, t in
             cfg.get("behaviours", {}).items() if isinstance(t, dict)}
    comps.setdefault("arbiter", str(cfg.get("arbiter", {}).get("component", "")))
    plugins = dict.fromkeys(p for tr in trials.values() for p in tr.plugins)
    labels = dict.fromkeys(lb for tr in trials.values() for lb in tr.behaviours)
    out = [Owner("plugins", p) for p in plugins]
    out += [Owner("behaviours", lb, comps.get(lb, "")) for lb in labels]
    return [o for o in out if any(o.data(tr) for tr in trials.values())]


def _length(tr: TrialLog, key: str) -> int:
    """The iterations of the trial, or of the evaluation ``key`` is logged for."""
    parts = key.split("/")
    if len(parts) >= 3 and parts[0] == "eval":
        return int(np.size(tr.episodes.get(f"eval/{parts[1]}/collision", [])))
    return int(np.size(tr.arrays.get("collision", [])))


def _kind(tr: TrialLog, key: str, value: Any) -> str:
    if not isinstance(value, np.ndarray):
        return "text" if isinstance(value, str) else "scalar"
    return "per-iteration series" if is_series(value, _length(tr, key)) else "array"


def inventory(owner: Owner, trials: dict[int, TrialLog]) -> Table:
    """Every key ``owner`` logged: kind, shape and type (of the first trial holding it),
    and in how many of the trials."""
    first: dict[str, tuple[str, str, str]] = {}
    count: dict[str, int] = {}
    for tr in trials.values():
        for key, v in owner.data(tr).items():
            count[key] = count.get(key, 0) + 1
            if key not in first:
                a = np.asarray(v)
                shape = "–" if a.ndim == 0 else " × ".join(map(str, a.shape))
                first[key] = (_kind(tr, key, v), shape, type(v).__name__ if a.ndim == 0
                              else str(a.dtype))
    rows = [[key, *first[key], f"{count[key]} of {len(trials)}"] for key in first]
    where = (f"/trials/NNNN/plugins/{owner.name}/" if owner.kind == "plugins"
             else f"/trials/NNNN/behaviours/{owner.name}/")
    return Table(f"What {owner.title.split(':')[0].lower()} logged ({where}; Python: "
                 f"TrialLog.{owner.kind}['{owner.name}'])",
                 ["Key", "Kind", "Shape", "Type", "Trials"], rows)


def scalar_table(owner: Owner, trials: dict[int, TrialLog]) -> Table | None:
    """A row per trial, a column per scalar ``owner`` logged (``None``: it logged none).

    The same numbers and bools are the summary columns ``<kind>.<name>.<key>`` of
    ``sitframe export`` and ``sitframe compare``."""
    keys: list[str] = []
    for tr in trials.values():
        keys += [k for k, v in owner.data(tr).items()
                 if not isinstance(v, np.ndarray) and k not in keys]
    if not keys:
        return None
    rows = []
    for k, tr in trials.items():
        data = owner.data(tr)
        rows.append([k, *(data.get(key, float("nan")) for key in keys)])
    return Table(f"Per-trial scalars of {owner.title.split(':')[0].lower()} (summary columns "
                 f"{owner.kind}.{owner.name}.<key>)", ["Trial", *keys], rows, digits=3)


def series(owner: Owner, trials: dict[int, TrialLog]) -> dict[str, dict[int, np.ndarray]]:
    """Key -> trial -> the per-iteration series ``owner`` logged under that key."""
    out: dict[str, dict[int, np.ndarray]] = {}
    for k, tr in trials.items():
        for key, v in owner.data(tr).items():
            if isinstance(v, np.ndarray) and is_series(v, _length(tr, key)):
                out.setdefault(key, {})[k] = v
    return out


def plot_series(title: str, key: str, values: dict[int, np.ndarray]) -> Figure:
    """One per-iteration series: each trial's line against the iteration (a 2-D series: a
    line per column of the first trial, or with more than :data:`MAX_LINES` columns a
    map of it)."""
    fig = Figure(figsize=(7, 3.4), layout="constrained")  # (no pyplot: nothing to close)
    ax = fig.add_subplot()
    first, a = next(iter(sorted(values.items())))
    if a.ndim == 2 and a.shape[1] > MAX_LINES:
        im = ax.imshow(np.asarray(a, dtype=float).T, aspect="auto", interpolation="nearest",
                       origin="lower", cmap="viridis")
        fig.colorbar(im, ax=ax, label=key)
        ax.set_ylabel("Column")
        ax.set_title(f"{title}, trial {first}", fontsize=10)
    elif a.ndim == 2:
        for j in range(a.shape[1]):
            ax.plot(np.arange(a.shape[0]), a[:, j], lw=0.9, label=f"column {j}")
        ax.set_ylabel(key)
        ax.legend(fontsize=7, ncols=2)
        ax.set_title(f"{title}, trial {first}", fontsize=10)
    else:
        for k, v in sorted(values.items()):
            ax.plot(np.arange(v.size), v, lw=0.9, alpha=0.8, label=f"trial {k}")
        ax.set_ylabel(key)
        if len(values) <= 12:
            ax.legend(fontsize=7, ncols=2)
        ax.set_title(title, fontsize=10)
    ax.set_xlabel("Iteration")
    ax.grid(alpha=0.3)
    return fig
