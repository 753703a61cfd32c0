"""Numbers behind the thesis's chapter-5 figures and tables, read from a log.

Everything here takes a :class:`sitframe.logs.reader.Log` (or a path to one) and/or a
:class:`sitframe.logs.reader.TrialLog` and returns numpy arrays, small dataclasses or
:class:`Table` objects; nothing draws. Figures are in
:mod:`sitframe.analysis.learning_plots`.

Definitions used throughout
---------------------------
* *Dominant situation* of an iteration: the situation with the largest
  membership of the reading the controller acted on (``argmax`` of the row of
  ``memberships``; ties go to the lower index).
* *Executed action* for a situation: the rule base the controller executed at
  that iteration (``behaviours/<label>/<output>/rule_base``, one action index per
  situation), looked up at the dominant situation.
* *Convergence iteration*: the iteration at which the learner froze its greedy
  rule base (thesis 4.6.4); ``None`` if it did not converge. Collisions
  "after convergence" are those of iterations ``>= convergence iteration``.
* Situations are numbered from 1 (``S1 ... Sc``) in labels, tables and
  figures, as in the thesis; array rows (``memberships[:, i]``, ``q[i]``)
  stay 0-based, so situation ``Sk`` is row ``k - 1``.

Why one module of this size: every table and array of the analysis API reads a log the same
few ways (``as_log``, ``_col``, ``_summary``); split by table they would repeat those.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sitframe.contract.records import summary_key
from sitframe.errors import InputError
from sitframe.logs.reader import Log, TrialLog, open_log
from sitframe.sim.world import World, parse_world
from sitframe.situations.clustering import (
    SELECTION_RULE,
    ClusteringTrials,
    SweepResult,
    rank_trials,
)
from sitframe.situations.fcm import MEASURE_DIRECTIONS
from sitframe.situations.labels import describe_prototypes

__all__ = [
    "CollisionIntervals",
    "Table",
    "as_log",
    "clustering_trials",
    "collision_intervals",
    "contexts_table",
    "convergence_iteration",
    "convergence_table",
    "evaluation_episodes",
    "exploration_counts",
    "learned_output",
    "lookup_table",
    "representative_trial",
    "reward_per_window",
    "robot_radius",
    "rule_base_table",
    "rule_bases_across_trials",
    "sensor_angles",
    "sensor_max_range",
    "situation_labels",
    "space_memberships",
    "space_of",
    "spaces_table",
    "sweep_result",
    "trial_situations",
]

LogLike = Log | str | os.PathLike[str]


# --------------------------------------------------------------------------- basics


def as_log(log: LogLike) -> Log:
    """Return ``log`` itself, or open the path with :func:`sitframe.logs.reader.open_log`.

    Raises
    ------
    InputError
        Missing file, not HDF5, not a sitframe log, unknown schema version.
    """
    return log if isinstance(log, Log) else open_log(log)


def _section(log: Log, name: str) -> dict[str, Any]:
    try:
        sec = log.config.get(name, {})
    except Exception:  # noqa: BLE001 - a log with a broken config is still analysable
        return {}
    return sec if isinstance(sec, dict) else {}


def parsed_worlds(log: Log) -> dict[str, World]:
    """The worlds the log holds, parsed (a damaged one is left out)."""
    out = {}
    for name, text in log.worlds.items():
        try:
            out[name] = parse_world(text, file=f"{log.path}:worlds/{name}")
        except InputError:
            continue
    return out


def sensor_angles(log: LogLike) -> np.ndarray:
    """Beam bearings [deg, + = left] of the run's sensor, from the log's sensor spec.

    Any layout (a front arc, a 360 deg ring). Logs written before the spec was
    logged: the ``[sensor]`` table's ``angles_deg``, else the Pioneer 2DX front
    ring (:attr:`sitframe.logs.reader.Log.sensor`).
    """
    return as_log(log).sensor.angles_deg


def sensor_max_range(log: LogLike) -> float:
    """Maximum range [m] of the run's sensor (:attr:`sitframe.logs.reader.Log.sensor`)."""
    return as_log(log).sensor.max_range


def robot_radius(log: LogLike) -> float:
    """Robot disc radius [m] from the ``[robot]`` config (default 0.15)."""
    return float(_section(as_log(log), "robot").get("radius", 0.15))


def situation_labels(log: LogLike, *, numbered: bool = True,
                     space: str = "default") -> list[str]:
    """One short label per situation, derived from the fitted prototypes, no two alike.

    Uses :func:`sitframe.situations.labels.describe_prototypes` on
    ``/cluster/state/centers`` with the log's sensor angles (each prototype's shape,
    with the open sides, the nearest direction, how close and at last a number where
    two would read alike). Without prototypes (another interpreter) the labels are just
    ``S1 ... Sc``. A situation space of its own (``space``, a ``[spaces.NAME]``) has the
    labels the run logged with it (its prototypes over the readings of its view).

    Parameters
    ----------
    log
        The log (or its path).
    numbered
        Prefix each label with ``"S{k}: "``, numbered from 1 (row ``k - 1``).
    space
        The situation space (default the ``[interpreter]``'s).

    Returns
    -------
    list of str
    """
    lg = as_log(log)
    if space != "default":
        logged = [str(x) for x in lg.space(space).get("labels", [])]
        return logged if numbered else [x.split(": ", 1)[-1] for x in logged]
    try:
        centers = np.asarray(lg.interpreter_state()["centers"], dtype=np.float64)
    except (InputError, KeyError):
        return [f"S{i + 1}" for i in range(_n_situations(lg))]
    angles = sensor_angles(lg)
    if centers.ndim != 2 or centers.shape[1] != angles.size:
        return [f"S{i + 1}" for i in range(centers.shape[0])]
    words = describe_prototypes(centers, angles)
    return [f"S{i}: {w}" if numbered else w for i, w in enumerate(words, start=1)]


def _n_situations(log: Log) -> int:
    try:
        return int(_section(log, "interpreter").get("c", 0))
    except (TypeError, ValueError):
        return 0


# ----------------------------------------------------------------------- clustering


def clustering_trials(log: LogLike) -> ClusteringTrials:
    """Rebuild the clustering stage (every FCM trial, the chosen one) from ``/cluster``.

    Ranks and eligibility are recomputed with
    :func:`sitframe.situations.clustering.rank_trials`; the chosen trial is the logged one.
    Initial centres are not logged (``init_centers`` is NaN).

    Raises
    ------
    InputError
        The log has no cluster stage, or it lacks trial centres / measures.
    """
    lg = as_log(log)
    st = lg.stage("cluster")
    for key in ("trial_centers", "trial_measures", "measure_names"):
        if key not in st:
            raise InputError(f"the cluster stage has no '{key}' (not an FCM clustering?)",
                             file=lg.path, key=f"cluster/{key}")
    measures = _measures(st, "trial_measures")
    missing = [k for k in MEASURE_DIRECTIONS if k not in measures]
    if missing:
        raise InputError(f"the cluster stage lacks the measures {missing}", file=lg.path,
                         key="cluster/measure_names")
    measures = {k: measures[k] for k in MEASURE_DIRECTIONS}
    centers = np.asarray(st["trial_centers"], dtype=np.float64)
    ranks, mean_rank, eligible, fallback = rank_trials(measures)
    interp = _section(lg, "interpreter")
    m = float(lg.interpreter_state().get("m", interp.get("m", 1.2))) if lg.has(
        "cluster/state") else float(interp.get("m", 1.2))
    T = centers.shape[0]
    return ClusteringTrials(
        c=int(centers.shape[1]), m=m, centers=centers, init_centers=np.full_like(centers, np.nan),
        measures=measures,
        n_iter=np.asarray(st.get("trial_n_iter", np.zeros(T)), dtype=np.int64),
        converged=np.asarray(st.get("trial_converged", np.ones(T)), dtype=bool),
        chosen=int(st.get("chosen", 0)), ranks=ranks, mean_rank=mean_rank,
        ranked_measures=tuple(k for k, v in MEASURE_DIRECTIONS.items() if v in ("max", "min")),
        eligible=eligible, fallback=bool(fallback), rule=str(st.get("rule", SELECTION_RULE)),
        tol=float(interp.get("tol", 1e-5)), max_iter=int(interp.get("max_iter", 300)),
    )


def _measures(stage: dict[str, Any], key: str) -> dict[str, np.ndarray]:
    """Measure name -> column of the cluster stage's (rows, measures) array ``key``."""
    names = stage["measure_names"]
    names = list(json.loads(names)) if isinstance(names, str) else [
        v.decode() if isinstance(v, bytes) else str(v) for v in np.asarray(names).ravel()]
    M = np.asarray(stage[key], dtype=np.float64)
    return {k: M[:, i] for i, k in enumerate(names)}


def sweep_result(log: LogLike) -> SweepResult | None:
    """The validity-vs-c sweep (thesis Fig. 4.5) if the log has one, else None.

    Only the chosen trial's measures per c are logged, so ``trials`` is empty,
    ``chosen`` is -1 and ``fallback`` is taken as ``min_card <= 0``.
    """
    lg = as_log(log)
    if not lg.has("cluster/sweep_c"):
        return None
    st = lg.stage("cluster")
    measures = _measures(st, "sweep_measures")
    cs = np.asarray(st["sweep_c"], dtype=np.int64)
    interp = _section(lg, "interpreter")
    fb = ~(measures.get("min_card", np.ones(cs.size)) > 0)
    return SweepResult(cs=cs, measures={k: measures[k] for k in MEASURE_DIRECTIONS if k in
                                        measures},
                       chosen=np.full(cs.size, -1), fallback=fb, trials=(),
                       m=float(interp.get("m", 1.2)), n_trials=int(interp.get("trials", 0)))


# ------------------------------------------------------------------------- learning


def learned_output(trial: TrialLog, label: str | None = None,
                   output: str = "heading") -> tuple[str, str]:
    """The (behaviour label, output) of a learned policy in the trial.

    Any learned behaviour counts: one whose trial logged a learned policy
    (:class:`sitframe.LearnedPolicy`, ``behaviours/<label>/policy/<output>``).

    Parameters
    ----------
    trial
        A trial read with :meth:`sitframe.logs.reader.Log.trial`.
    label
        Behaviour label; default the first behaviour that learned ``output``.
    output
        Output name (e.g. ``"heading"`` or ``"speed"``); if ``label`` is None
        and no behaviour learned ``output``, any learned output is taken.

    Raises
    ------
    InputError
        No behaviour of the trial learned anything (or ``label`` did not).
    """
    learned = [(lb, out) for lb, pol in trial.policies.items() for out in pol.outputs]
    if label is not None:
        learned = [x for x in learned if x[0] == label]
    pick = [x for x in learned if x[1] == output] or learned
    if not pick:
        raise InputError(f"trial {trial.index} has no learned rule base"
                         + (f" for behaviour '{label}'" if label else "")
                         + f" (behaviours: {sorted(trial.behaviours)})", key="behaviours")
    return pick[0]


def space_of(trial: TrialLog, label: str) -> str:
    """The situation space behaviour ``label`` (or ``"arbiter"``) of the trial read
    (``"default"`` in a run with one space)."""
    return str(trial.behaviours.get(label, {}).get("space", "default"))


def space_memberships(trial: TrialLog, space: str = "default") -> np.ndarray:
    """(L, c) memberships of the trial's iterations in situation space ``space``."""
    key = "memberships" if space == "default" else f"spaces/{space}/memberships"
    if key not in trial.arrays:
        raise InputError(f"trial {trial.index} has no memberships of space '{space}'",
                         key=f"trials/{trial.index:04d}/{key}")
    return np.asarray(trial.arrays[key])


def _policy_output(trial: TrialLog, label: str, output: str) -> Any:
    pol = trial.learned_policy(label)
    if pol is None or output not in pol.outputs:
        raise InputError(f"behaviour '{label}' logged no learned {output}",
                         key=f"behaviours/{label}/policy/{output}")
    return pol.outputs[output]


def exploration_counts(trial: TrialLog, label: str | None = None, output: str = "heading",
                       *, start: int = 0, stop: int | None = None) -> np.ndarray:
    """How often each (dominant situation, executed action) pair occurred (Fig. 5.4).

    Parameters
    ----------
    trial
        A learning trial.
    label, output
        Which learned rule base (see :func:`learned_output`).
    start, stop
        Iteration window ``[start, stop)``; default the whole trial.

    Returns
    -------
    ndarray of int, shape (c, A)
        ``counts[s, a]`` = iterations in which situation ``s`` was dominant and
        its rule executed action ``a`` (indices into the singletons). Sums to
        the number of iterations in the window.
    """
    label, output = learned_output(trial, label, output)
    u = space_memberships(trial, space_of(trial, label))
    if f"{output}/rule_base" not in trial.behaviours[label]:
        raise InputError(f"behaviour '{label}' logged no per-iteration rule base "
                         f"('{output}/rule_base', as fuzzy-q does), so the executed actions "
                         "are unknown", key=f"behaviours/{label}/{output}/rule_base")
    rb = np.asarray(trial.behaviours[label][f"{output}/rule_base"])
    A = _policy_output(trial, label, output).actions.size
    n = min(u.shape[0], rb.shape[0])
    sl = slice(start, n if stop is None else min(stop, n))
    u, rb = u[sl], rb[sl]
    dom = u.argmax(axis=1)
    act = rb[np.arange(dom.size), dom].astype(np.intp)
    counts = np.zeros((u.shape[1], A), dtype=np.int64)
    np.add.at(counts, (dom, act), 1)
    return counts


def convergence_iteration(trial: TrialLog, label: str | None = None) -> int | None:
    """Iteration at which the trial's learned rule base was frozen, or None."""
    data = trial.behaviours.get(label) if label else None
    if data is None:
        try:
            data = trial.behaviours[learned_output(trial)[0]]
        except InputError:
            data = {}
    it = data.get("convergence_iteration", trial.summary.get("convergence_iteration", -1))
    conv = data.get("converged", trial.summary.get("converged", False))
    return int(it) if conv and it is not None and int(it) >= 0 else None


@dataclass(frozen=True)
class CollisionIntervals:
    """Collisions of a run and the iterations between them (Figs. 5.5, 5.6).

    Attributes
    ----------
    iterations : ndarray of int, shape (k,)
        0-based iteration of each collision.
    intervals : ndarray of int, shape (k,)
        Iterations since the previous collision (for the first one: since the
        start, i.e. ``iterations[0] + 1``). One iteration is 1.5 s.
    n_iterations : int
        Length of the run.
    """

    iterations: np.ndarray
    intervals: np.ndarray
    n_iterations: int


def collision_intervals(collision: np.ndarray) -> CollisionIntervals:
    """Iterations between successive collisions of a boolean per-iteration array."""
    c = np.asarray(collision, dtype=bool).ravel()
    it = np.flatnonzero(c)
    iv = np.diff(np.r_[-1, it])
    return CollisionIntervals(it.astype(np.int64), iv.astype(np.int64), int(c.size))


def reward_per_window(reward: np.ndarray, window: int = 50) -> np.ndarray:
    """Mean reward over consecutive windows of ``window`` iterations (Figs. 5.7, 5.8).

    Returns
    -------
    ndarray, shape (ceil(L / window),)
        Entry ``k`` is the mean over iterations ``[k*window, (k+1)*window)``;
        the last window may be shorter.
    """
    if window < 1:
        raise ValueError(f"window must be >= 1 iteration, got {window}")
    r = np.asarray(reward, dtype=np.float64).ravel()
    if r.size == 0:
        return np.zeros(0)
    starts = np.arange(0, r.size, window)
    return np.add.reduceat(r, starts) / np.diff(np.r_[starts, r.size])


def episode_rows(n: int, first: np.ndarray, n_rows: int) -> tuple[np.ndarray, np.ndarray]:
    """For a chain of episodes (``first``: each one's first iteration) of ``n`` iterations:
    the pose row each iteration starts from and the episode it belongs to, both (n,).

    A batch of goal episodes ends each episode in a pose row of its own
    (``n_rows == n + episodes``), so iteration ``i`` of episode ``e`` starts from
    row ``i + e``; a learning chain (``n + 1`` rows) starts each from row ``i``.
    """
    f = np.asarray(first, dtype=np.intp)
    episode = np.searchsorted(f, np.arange(n), side="right") - 1
    it = np.arange(n)
    return (it + episode if n_rows == n + len(f) else it), episode


def evaluation_episodes(trial: TrialLog) -> dict[str, dict[str, np.ndarray]]:
    """Evaluation runs of a trial: world name -> {``pose`` (n+1, 3), ``collision`` (n,), ...}.

    Logs written since evaluations keep more also hold ``contact`` (n, 2),
    ``command`` (n, 2), ``nearest`` (n,), ``reading`` (n, d) and ``memberships``
    (n, c) per world (the evaluation figure marks collisions at the contact).
    A log from before contract v2 names the reading ``sonar``; it is given as
    ``reading`` too.
    """
    out: dict[str, dict[str, np.ndarray]] = {}
    for key, val in trial.episodes.items():
        parts = key.split("/")
        if len(parts) == 3 and parts[0] == "eval":
            out.setdefault(parts[1], {})[parts[2]] = np.asarray(val)
    for d in out.values():
        if "reading" not in d and "sonar" in d:
            d["reading"] = d["sonar"]
    return {w: d for w, d in out.items() if "pose" in d}


def collision_points(pose: np.ndarray, iterations: np.ndarray,
                     contact: np.ndarray | None = None,
                     rows: np.ndarray | None = None) -> np.ndarray:
    """Where the collisions of ``iterations`` (k,) happened, (k, 2) [m].

    The logged contact point (``contact``, (L, 2)); where there is none (not
    logged, or NaN), the robot's position after the colliding iteration
    (``pose`` row ``i + 1``, or ``rows + 1`` when the iterations start from
    other rows, (k,): a batch of episodes has one more pose row per episode).
    """
    it = np.asarray(iterations, dtype=np.intp)
    after = np.asarray(pose)[(it if rows is None else np.asarray(rows, np.intp)) + 1, :2]
    if contact is None:
        return after
    at = np.asarray(contact, dtype=np.float64)[it]
    return np.where(np.isfinite(at).all(axis=1)[:, None], at, after)


def _summary(lg: Log, *, plugins: bool = False) -> np.ndarray:
    """The root summary table, restricted to trials whose group is in the log (with
    ``plugins``, and the plugins' per-trial scalars: :meth:`Log.summary`)."""
    if plugins:
        return lg.summary(plugins=True)
    s = lg.summary()
    if s.size:
        s = s[np.isin(s["trial"], lg.trial_indices())]
    return s


def representative_trial(log: LogLike) -> int | None:
    """The trial the per-trial figures show by default.

    The converged trial whose convergence iteration is the median of the
    converged trials (the lower one for an even count); if none converged, the
    trial with the lowest index. None when the log has no finished trial.
    """
    lg = as_log(log)
    s = _summary(lg)
    if s.size == 0:
        return None
    names = s.dtype.names or ()
    if "converged" in names and "convergence_iteration" in names:
        ok = s["converged"] > 0.5
        if ok.any():
            rows = s[ok]
            order = np.argsort(rows["convergence_iteration"], kind="stable")
            return int(rows["trial"][order[(len(order) - 1) // 2]])
    return int(np.min(s["trial"]))


# --------------------------------------------------------------------------- tables


def _fmt(v: Any, digits: int) -> str:
    if v is None:
        return ""
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        if not math.isfinite(float(v)):
            return ""
        return f"{float(v):.{digits}f}"
    return str(v)


@dataclass
class Table:
    """A small result table that renders as Markdown or CSV.

    Attributes
    ----------
    title : str
        One line saying what the table is (used as Markdown caption).
    columns : list of str
        Column headers (units in brackets).
    rows : list of list
        Cell values: str, int, float (NaN = empty cell), bool (yes/no) or None.
    notes : list of str
        Lines printed under the Markdown table.
    digits : int
        Decimals for floats.
    """

    title: str
    columns: list[str]
    rows: list[list[Any]]
    notes: list[str] = field(default_factory=list)
    digits: int = 2

    def column(self, name: str) -> list[Any]:
        """The values of one column."""
        i = self.columns.index(name)
        return [r[i] for r in self.rows]

    def cells(self) -> list[list[str]]:
        """The rows as text, ``"–"`` for an empty cell (Markdown and HTML)."""
        return [[_fmt(v, self.digits) or "–" for v in r] for r in self.rows]

    def numeric(self) -> list[bool]:
        """Per column: whether every cell is a number (such columns are right-aligned)."""
        return [all(_is_num(r[i]) for r in self.rows) for i in range(len(self.columns))]

    def to_markdown(self) -> str:
        """GitHub-flavoured Markdown: bold title line, table, notes."""
        lines = [f"**{self.title}**", "",
                 "| " + " | ".join(self.columns) + " |",
                 "|" + "|".join("---:" if n else ":---" for n in self.numeric()) + "|"]
        lines += ["| " + " | ".join(c.replace("|", "\\|") for c in r) + " |"
                  for r in self.cells()]
        if self.notes:
            lines += [""] + [f"{n}  " for n in self.notes]
        return "\n".join(lines) + "\n"

    def to_csv(self) -> str:
        """CSV with a header row; floats at full precision, NaN/None as empty cells."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.columns)
        for r in self.rows:
            w.writerow([_csv_cell(v) for v in r])
        return buf.getvalue()

    def save(self, stem: str | os.PathLike[str]) -> tuple[str, str]:
        """Write ``<stem>.md`` and ``<stem>.csv``; return both paths."""
        md, cs = f"{os.fspath(stem)}.md", f"{os.fspath(stem)}.csv"
        with open(md, "w", encoding="utf-8") as f:
            f.write(self.to_markdown())
        with open(cs, "w", encoding="utf-8", newline="") as f:
            f.write(self.to_csv())
        return md, cs


def _is_num(v: Any) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(
        v, bool | np.bool_) or v is None


def _csv_cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, bool | np.bool_):
        return int(bool(v))
    if isinstance(v, float | np.floating):
        return "" if not math.isfinite(float(v)) else repr(float(v))
    if isinstance(v, np.integer):
        return int(v)
    return v


def _deg(a: float) -> str:
    return f"{a:+g}°" if a else "0°"


def _num(a: float) -> int | float:
    """An action value as int when it is integral (90.0 -> 90), for tables."""
    a = float(a)
    return int(a) if a.is_integer() else a


def lookup_table(log: LogLike, trial: int | TrialLog, label: str | None = None,
                 output: str = "heading") -> Table:
    """The learned lookup table Q (situations x actions) of one trial (Tables 5.4, 5.5).

    Q is ``behaviours/<label>/<output>/q``, the table at the end of the trial,
    which is the table at convergence when the trial converged (learning stops
    then). The last column is the greedy action (largest Q).

    Returns
    -------
    Table
        One row per situation: ``Situation``, ``Description``, one column per
        action (headers in degrees), ``Greedy [deg]``.
    """
    lg = as_log(log)
    tr = trial if isinstance(trial, TrialLog) else lg.trial(trial)
    label, output = learned_output(tr, label, output)
    q = np.asarray(tr.behaviours[label][f"{output}/q"], dtype=np.float64)
    singles = _policy_output(tr, label, output).actions
    shown, labels, notes = trial_situations(lg, tr, q.shape[0], space_of(tr, label))
    heading = output == "heading"
    cols = (["Situation", "Description"]
            + [_deg(float(a)) if heading else f"{a:g}" for a in singles]
            + ["Greedy [deg]" if heading else f"Greedy ({output})"])
    rows = [[i + 1, w, *map(float, q[i]), _num(singles[int(np.argmax(q[i]))])]
            for i, w in zip(shown, labels, strict=True)]
    conv = convergence_iteration(tr, label)
    when = (f"at convergence (iteration {conv})" if conv is not None
            else f"after {tr.arrays['collision'].size} iterations, not converged")
    return Table(f"Lookup table Q of trial {tr.index}, behaviour '{label}' ({output}), {when}",
                 cols, rows, notes=notes)


def trial_situations(lg: Log, tr: TrialLog, c: int, space: str = "default"
                     ) -> tuple[list[int], list[str], list[str]]:
    """The situations a trial's tables show: their rows (0-based), descriptions and notes.

    With a fixed interpreter: all ``c``, described by the log's prototypes. With evolving
    situations (the trial logged its final ones, ``situations/state``): only the
    situations alive at the trial's end, each described by its final prototype (ids keep
    their numbers, so row ``k`` is still situation ``k + 1`` of the memberships and Q); the
    slots never used, merged or pruned away are left out and a note says how many.
    """
    st = tr.situations_part("state") if space == "default" else {}
    if "ids" not in st:
        return list(range(c)), _labels_for(lg, c, space), []
    ids = np.asarray(st["ids"], dtype=np.intp)
    centers = np.asarray(st["centers"], dtype=np.float64)
    angles = sensor_angles(lg)
    words = (describe_prototypes(centers, angles) if centers.ndim == 2 and ids.size
             and centers.shape[1] == angles.size else [""] * ids.size)
    order = np.argsort(ids)
    shown = [int(ids[i]) for i in order if ids[i] < c]
    notes = [f"Evolving situations: the {len(shown)} alive at the trial's end, each described "
             f"by its final prototype; the other {c - len(shown)} of the {c} slots (never "
             "used, or merged or pruned away) are left out."] if len(shown) < c else []
    return shown, [words[i] for i in order if ids[i] < c], notes


def _labels_for(log: Log, c: int, space: str = "default") -> list[str]:
    labels = situation_labels(log, numbered=False, space=space)
    return labels if len(labels) == c else [""] * c


def rule_base_table(log: LogLike, trial: int | TrialLog, label: str | None = None,
                    output: str = "heading") -> Table:
    """The learned rule base of one trial (Tables 5.7, 5.8) with each situation's max Q.

    Returns
    -------
    Table
        One row per situation: ``Situation``, ``Description``, ``Action [deg]``
        (the converged rule base, or the greedy one if the trial did not
        converge), ``Max Q`` (the situation's desirability, Table 5.6) and
        ``Dominant [%]`` (share of the trial's iterations in which the situation
        was dominant).
    """
    lg = as_log(log)
    tr = trial if isinstance(trial, TrialLog) else lg.trial(trial)
    label, output = learned_output(tr, label, output)
    po = _policy_output(tr, label, output)
    singles = po.actions
    q = None if po.q is None else np.asarray(po.q, dtype=np.float64)
    pol = np.asarray(po.rules, dtype=np.intp)
    c = pol.size
    shown, labels, notes = trial_situations(lg, tr, c, space_of(tr, label))
    u = space_memberships(tr, space_of(tr, label))
    counts = np.bincount(u.argmax(axis=1), minlength=c) if u.size else np.zeros(c)
    share = 100.0 * counts / max(int(counts.sum()), 1)
    head = f"Action [{po.unit}]" if po.unit else f"Action ({output})"
    rows = [[i + 1, w, _num(singles[pol[i]]),
             float(q[i].max()) if q is not None else float("nan"), float(share[i])]
            for i, w in zip(shown, labels, strict=True)]
    conv = convergence_iteration(tr, label)
    state = (f"converged at iteration {conv}" if conv is not None
             else "not converged: greedy rule base of the final Q")
    return Table(f"Learned rule base of trial {tr.index}, behaviour '{label}' ({output}), "
                 f"{state}", ["Situation", "Description", head, "Max Q", "Dominant [%]"], rows,
                 notes=notes, digits=1)


def rule_bases_across_trials(log: LogLike, label: str | None = None,
                             output: str = "heading", *,
                             read: Callable[[int], TrialLog] | None = None) -> Table:
    """Every trial's learned action per situation, and the most frequent one (Tables A.2/A.3).

    ``read`` reads trial ``k`` (default :meth:`sitframe.logs.reader.Log.trial`; a caller
    that already holds the trials passes its cache).

    Returns
    -------
    Table
        One row per situation: ``Situation``, ``Description``, one column per
        trial (``T0``, ``T1``, ...; action values, degrees for heading),
        ``Most frequent``, ``Agreement [%]`` (share of trials with that action).
        With evolving situations, the rows are the fitted situations every trial
        starts from (a trial's own situations differ between trials), empty where
        a trial merged or pruned one, and the share counts the trials that kept it.
    """
    lg = as_log(log)
    idx = lg.trial_indices()
    acts: list[np.ndarray] = []
    conv: list[bool] = []
    alive: list[np.ndarray | None] = []  # evolving situations: the ids alive at a trial's end
    space = "default"
    for k in idx:
        tr = (read or lg.trial)(k)
        lb, out = learned_output(tr, label, output)
        acts.append(_policy_output(tr, lb, out).values())
        conv.append(convergence_iteration(tr, lb) is not None)
        space = space_of(tr, lb)
        ids = tr.situations_part("state").get("ids") if space == "default" else None
        alive.append(None if ids is None else np.asarray(ids, dtype=np.intp))
    if not acts:
        raise InputError("the log has no finished learning trial", file=lg.path, key="trials")
    A = np.stack(acts, axis=1).astype(np.float64)  # (c, T)
    notes = ["* trial did not converge (greedy rule base of its final Q)"] if not all(conv) else []
    shown = range(A.shape[0])
    if any(a is not None for a in alive):  # evolving: the seeded situations, where alive
        labels = situation_labels(lg, numbered=False)
        shown = range(min(len(labels), A.shape[0]))
        for t, a in enumerate(alive):
            if a is not None:
                A[np.setdiff1d(np.arange(A.shape[0]), a), t] = np.nan
        notes.append(f"Evolving situations: the {len(shown)} fitted ones every trial starts "
                     "from (– where a trial merged or pruned it); the situations a trial made "
                     "differ from trial to trial and are in each trial's rule base.")
    else:
        labels = _labels_for(lg, A.shape[0], space)
    rows = []
    for i in shown:
        vals, cnt = np.unique(A[i][~np.isnan(A[i])], return_counts=True)
        best = float(vals[np.argmax(cnt)]) if cnt.size else float("nan")
        rows.append([i + 1, labels[i], *map(float, A[i]), best,
                     100.0 * cnt.max() / cnt.sum() if cnt.size else float("nan")])
    cols = ["Situation", "Description"] + [f"T{k}" + ("" if c else "*")
                                           for k, c in zip(idx, conv, strict=True)]
    return Table(f"Learned {output} action per situation in each trial "
                 f"({'degrees' if output == 'heading' else output})",
                 cols + ["Most frequent", "Agreement [%]"], rows, notes=notes, digits=0)


def _eval_worlds(s: np.ndarray) -> list[str]:
    """The evaluation worlds of a summary table (those with a collision rate)."""
    head, tail = summary_key("eval", "", sep="."), summary_key("", "collisions_per_1000", sep=".")
    return [n[len(head):-len(tail)] for n in s.dtype.names or ()
            if n.startswith(head) and n.endswith(tail)]


def _col(s: np.ndarray, name: str, world: str | None = None) -> np.ndarray:
    """Column ``name`` (of evaluation ``world``, if given) as floats; NaN if absent."""
    if world is not None:
        name = summary_key("eval", world, name, sep=".")
    names = s.dtype.names or ()
    return np.asarray(s[name], dtype=np.float64) if name in names else np.full(s.size, np.nan)


def convergence_table(log: LogLike) -> Table:
    """Convergence and quality of every trial (Table 5.9, extended).

    Read from the root ``/summary`` table (one row per finished trial).

    Returns
    -------
    Table
        One row per trial, then a ``mean`` row (convergence iteration averaged
        over converged trials only, other columns over all trials). Columns:
        ``Trial``, ``Converged``, ``Convergence iteration``,
        ``Collisions after conv. [/1000 it.]``, ``Collisions [/1000 it.]``,
        ``Coverage``, then per evaluation world ``<w> collisions [/1000 it.]``
        and ``<w> coverage`` (fraction of free 0.5 m cells visited).
    """
    lg = as_log(log)
    s = _summary(lg)
    worlds = _eval_worlds(s)
    conv = _col(s, "converged") > 0.5
    it = np.where(conv, _col(s, "convergence_iteration"), np.nan)
    series: list[tuple[str, np.ndarray]] = [
        ("Convergence iteration", it),
        ("Collisions after conv. [/1000 it.]", _col(s, "collisions_per_1000_after_convergence")),
        ("Collisions [/1000 it.]", _col(s, "collisions_per_1000")),
        ("Coverage", _col(s, "coverage")),
    ]
    for w in worlds:
        series += [(f"{w} collisions [/1000 it.]", _col(s, "collisions_per_1000", w)),
                   (f"{w} coverage", _col(s, "coverage", w))]
    rows: list[list[Any]] = [
        [int(s["trial"][j]), bool(conv[j])]
        + [int(v[j]) if v is it and np.isfinite(v[j]) else float(v[j]) for _n, v in series]
        for j in range(s.size)]
    if s.size:  # convergence iteration: over the converged trials (the others are NaN)
        rows.append(["mean", f"{int(conv.sum())}/{s.size}"]
                    + [float(np.nanmean(v)) if np.isfinite(v).any() else math.nan
                       for _n, v in series])
    notes = ["Coverage = fraction of the world's free 0.5 m grid cells visited.",
             "Mean convergence iteration over converged trials only."]
    if not lg.complete:
        notes.append(f"Log status is '{lg.status}': only finished trials are listed.")
    return Table(f"Convergence of {s.size} learning trials ({os.path.basename(lg.path)})",
                 ["Trial", "Converged", *[n for n, _ in series]], rows, notes=notes, digits=2)


def spaces_table(log: LogLike) -> Table:
    """The situation spaces of a run: the ``[interpreter]``'s (``default``) and each
    ``[spaces.NAME]``, with their interpreter, number of situations, the readings they see,
    where their situations came from and which behaviours (and arbiter) read them."""
    lg = as_log(log)
    cfg = lg.config
    angles = sensor_angles(lg)
    spaces = cfg.get("spaces", {})
    readers: dict[str, list[str]] = {"default": []}
    for lb, t in cfg.get("behaviours", {}).items():
        readers.setdefault(str(t.get("space", "default")), []).append(lb)
    arb = cfg.get("arbiter", {})
    if "space" in arb or arb.get("reward"):
        readers.setdefault(str(arb.get("space", "default")), []).append("arbiter")
    interp = cfg.get("interpreter", {})
    c0 = len(situation_labels(lg))
    src0 = cfg.get("experiment", {}).get("clusters_from") or "fitted"
    rows = [["default", str(interp.get("component", "")), c0,
             " ".join(f"{a:+g}" for a in angles), src0, ", ".join(readers["default"])]]
    for name in lg.space_names():
        sp = lg.space(name)
        view = [int(v) for v in np.asarray(sp.get("view", []))]
        rows.append([name, str(sp.get("component", spaces.get(name, {}).get("component", ""))),
                     len(sp.get("labels", [])), " ".join(f"{angles[v]:+g}" for v in view),
                     str(sp.get("source", "")), ", ".join(readers.get(name, []))])
    return Table("Situation spaces: each behaviour's (and the arbiter's) own situations",
                 ["Space", "Interpreter", "Situations", "Readings [deg]", "Situations from",
                  "Read by"], rows)


def contexts_table(log: LogLike, *, read: Callable[[int], TrialLog] | None = None) -> Table:
    """Per context of a learning arbiter, over the trials: learning iterations spent in it
    (visits), rule updates, and in how many trials it converged (``arbitration/context_*``
    of ``fuzzy-q-arbiter``: a context rarely visited is one learning may leave untrained)."""
    lg = as_log(log)
    rows_v, rows_u, rows_c, names = [], [], [], None
    for k in lg.trial_indices():
        b = (read or lg.trial)(k).behaviours.get("arbiter", {})
        if "arbitration/context_visits" not in b:
            continue
        names = list(b["arbitration/contexts"]) if isinstance(b["arbitration/contexts"], list) \
            else json.loads(b["arbitration/contexts"])
        rows_v.append(np.asarray(b["arbitration/context_visits"], float))
        rows_u.append(np.asarray(b["arbitration/context_updates"], float))
        rows_c.append(np.asarray(b["arbitration/context_converged_at"]) >= 0)
    if names is None:
        raise InputError("the log's arbiter logged no per-context counts "
                         "(arbitration/context_visits)", file=lg.path, key="arbiter")
    V, U, C = np.stack(rows_v), np.stack(rows_u), np.stack(rows_c)
    rows = [[n, float(np.median(V[:, j])), float(V[:, j].min()), float(np.median(U[:, j])),
             float(U[:, j].min()), f"{int(C[:, j].sum())}/{len(C)}"]
            for j, n in enumerate(names)]
    return Table("Learning arbiter: visits, updates and convergence per context, over trials",
                 ["Context", "Visits (median)", "Visits (fewest)", "Updates (median)",
                  "Updates (fewest)", "Converged (trials)"], rows, digits=0)
