"""Write every figure and table a log supports into a folder, with index.html and index.md.

This is what ``sitframe analyse LOG [-o DIR]`` runs; from Python::

    from sitframe.analysis import analyse
    report = analyse("logs/obstacle-avoidance.h5")
    print(report.out_dir, report.problems)

Per run: cluster prototypes (Fig. 5.2), validity per FCM trial (Fig. 5.1) and
per c (Fig. 4.5, if the log has a sweep), learning curves of all trials, the
convergence table (Table 5.9) and the learned action per situation in every
trial (Tables A.2/A.3). Per analysed trial (default: the representative one,
see :func:`sitframe.analysis.results.representative_trial`): exploration
(Fig. 5.4), iterations between collisions (Fig. 5.5), mean reward per 50
iterations (Fig. 5.7), the learning path after convergence (Fig. 5.10), the
evaluation paths (Fig. 5.11), lookup table (Table 5.4) and rule base
(Table 5.7).

Incomplete logs (status other than ``complete``, stages or trials missing) are
analysed as far as they go; what is missing is listed in ``index.md`` and in
:attr:`AnalysisReport.problems`.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cache
from itertools import groupby
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.analysis import results as R
from sitframe.analysis.report_html import write_report_html
from sitframe.contract.records import summary_key
from sitframe.errors import InputError
from sitframe.logs.reader import Log, TrialLog
from sitframe.situations.labels import describe_prototypes

__all__ = ["AnalysisReport", "analyse", "log_problems"]

_EXPECTED = (InputError, KeyError, ValueError, IndexError, OSError)


@dataclass
class AnalysisReport:
    """What :func:`analyse` wrote.

    Attributes
    ----------
    log : str
        The analysed log.
    out_dir : str
        Folder with the figures, tables and ``index.md``.
    status : str
        The log's status attribute.
    files : list of (section, file name, caption)
        Everything written (file names relative to ``out_dir``; a table is one
        entry for its ``.md`` with the ``.csv`` next to it).
    problems : list of str
        Why the log is incomplete (empty for a complete log).
    skipped : list of str
        Figures or tables that could not be made, and why.
    trials : list of int
        Trials that got per-trial figures.
    seconds : float
        Wall time.
    """

    log: str
    out_dir: str
    status: str
    files: list[tuple[str, str, str]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    trials: list[int] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def index(self) -> str:
        """Path of ``index.md``."""
        return os.path.join(self.out_dir, "index.md")

    @property
    def html(self) -> str:
        """Path of ``index.html`` (the page with every figure, table and the replay)."""
        return os.path.join(self.out_dir, "index.html")


def log_problems(log: R.LogLike) -> list[str]:
    """Plain-language list of what a log is missing (empty for a complete log).

    Checks the status attribute, the stages the config asked for
    (``experiment.stages``), the number of finished trials against
    ``n_trials``, and, in a run that learns and evaluates, each finished
    trial's evaluations against the worlds the others were evaluated in
    (the evaluation protocol's, e.g. a goal run's ``[goal] worlds``; where no
    trial has one, ``[evaluate] worlds``).
    """
    lg = R.as_log(log)
    out: list[str] = []
    if lg.status != "complete":
        out.append(f"log status is '{lg.status}', not 'complete' (the run did not finish)")
    try:
        cfg = lg.config
    except Exception:  # noqa: BLE001 - a broken config must not stop the analysis
        return out + ["the log's config attribute cannot be parsed"]
    stages = list(cfg.get("experiment", {}).get("stages", []))
    reuse = bool(cfg.get("experiment", {}).get("clusters_from"))
    for st in ("collect", "cluster"):
        if st in stages and not reuse and not lg.has(st):
            out.append(f"stage '{st}' is missing (no /{st} group)")
    have = lg.trial_indices()
    if "learn" in stages:
        try:
            n = int(lg.attrs.get("n_trials", cfg.get("experiment", {}).get("trials", 0)))
        except (TypeError, ValueError):
            n = 0
        missing = sorted(set(range(n)) - set(have))
        if missing:
            out.append(f"{len(missing)} of {n} learning trials missing: {_ranges(missing)}")
    if "evaluate" in stages and "learn" in stages and have:  # (else the batches are trials)
        with lg._file() as f:
            done = {k: {w for w, e in f.get(f"trials/{k:04d}/episodes/eval", {}).items()
                        if "pose" in e} for k in have}
        # The worlds of the run's evaluation protocol (``[evaluate] worlds`` for the frozen
        # one, a goal run's ``[goal] worlds``, ...), as the log recorded them; a log written
        # before it did: the worlds any trial was evaluated in, else ``[evaluate]``'s.
        try:
            worlds = list(json.loads(lg.attrs["evaluation"])["worlds"])
        except (KeyError, TypeError, ValueError):
            worlds = sorted(set().union(*done.values())) or \
                list(cfg.get("evaluate", {}).get("worlds", []))
        for w in worlds:
            ks = [k for k in have if w not in done[k]]
            if ks:
                out.append(f"evaluation in '{w}' missing for trial(s) {_ranges(ks)}")
    return out


def _ranges(ks: Iterable[int]) -> str:
    """``[0, 1, 2, 5]`` -> ``"0-2, 5"``."""
    runs = [[k for _i, k in g] for _d, g in groupby(enumerate(sorted(ks)), lambda p: p[1] - p[0])]
    return ", ".join(str(r[0]) if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs)


class _Writer:
    def __init__(self, report: AnalysisReport, dpi: int) -> None:
        self.r = report
        self.dpi = dpi
        self.tables: dict[str, R.Table] = {}  # stem -> table, for the HTML page

    def _make(self, name: str, make: Callable[[], Any]) -> Any:
        """``make()``, or None when the log does not support it (noted as skipped)."""
        try:
            return make()
        except _EXPECTED as exc:
            self.r.skipped.append(f"{name}: {exc}")
            return None

    def figure(self, section: str, name: str, caption: str, make: Callable[[], Any]) -> None:
        if (fig := self._make(name, make)) is None:
            return
        fig.savefig(os.path.join(self.r.out_dir, name), dpi=self.dpi)
        self.r.files.append((section, name, caption))

    def table(self, section: str, stem: str, caption: str, make: Callable[[], R.Table]) -> None:
        if (t := self._make(f"{stem}.md/.csv", make)) is None:
            return
        t.save(os.path.join(self.r.out_dir, stem))
        self.tables[stem] = t
        self.r.files.append((section, f"{stem}.md", caption + f" ([CSV]({stem}.csv))"))


def analyse(
    log: R.LogLike,
    out_dir: str | os.PathLike[str] | None = None,
    *,
    trials: Iterable[int] | str | None = None,
    window: int = 50,
    path_iterations: int = 400,
    dpi: int = 200,
) -> AnalysisReport:
    """Write the figures (PNG) and tables (Markdown + CSV) a log supports, and ``index.md``.

    Parameters
    ----------
    log
        The log or its path (bad input raises :class:`~sitframe.errors.InputError`).
    out_dir
        Output folder; default ``<log folder>/<log stem>-analysis``. Created.
    trials
        Trials that get per-trial figures: an iterable of indices, ``"all"``,
        or None for the representative trial only.
    window
        Iterations per reward window (thesis: 50).
    path_iterations
        Iterations of each drawn path: the learning path starts at convergence
        (or is the last ``path_iterations`` iterations of an unconverged trial);
        evaluation paths start at 0.
    dpi
        Resolution of the PNGs.

    Returns
    -------
    AnalysisReport
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from sitframe.analysis import clustering_plots as CP  # matplotlib: start-up time
    from sitframe.analysis import learning_plots as LP  # matplotlib: start-up time

    t0 = time.perf_counter()
    lg = R.as_log(log)
    out = Path(out_dir) if out_dir is not None else Path(lg.path).with_name(
        Path(lg.path).stem + "-analysis")
    lg.check()  # a damaged log fails here, before the output folder is created
    if trials not in (None, "all"):  # so does a trial the log does not have
        have = lg.trial_indices()
        bad = [int(k) for k in trials if int(k) not in have]  # type: ignore[union-attr]
        if bad:
            raise InputError(f"the log has no trial(s) {bad}; it has {_ranges(have)}",
                             file=lg.path, key="--trial")
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        # everything is written into a scratch folder inside ``out`` and moved up at the end:
        # an analysis that fails half-way leaves ``out`` as it was
        scratch = Path(tempfile.mkdtemp(prefix=".analysis-", suffix=".part", dir=out))
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc.strerror}", file=str(out),
                         key="-o") from None
    try:
        rep = AnalysisReport(lg.path, str(scratch), lg.status)
        rep.problems = log_problems(lg)
        W = _Writer(rep, dpi)
        radius = R.robot_radius(lg)

        _clustering_section(W, lg, rep, CP)
        if lg.space_names():
            _spaces_section(W, lg, rep, CP)

        # ------------------------------------------------------------- learning
        idx = lg.trial_indices()
        get = cache(lg.trial)  # each trial read once
        if idx:
            _learning_section(W, lg, rep, trials, idx, get, window, path_iterations,
                              radius, LP)
            _plugin_sections(W, lg, {k: get(k) for k in idx})
        rep.seconds = time.perf_counter() - t0
        write_report_html(rep, lg, {k: get(k) for k in idx}, W.tables)
        rep.seconds = time.perf_counter() - t0
        _write_index(rep, lg)
        for name in sorted(os.listdir(scratch)):
            os.replace(scratch / name, out / name)
        scratch.rmdir()
    except BaseException as exc:
        shutil.rmtree(scratch, ignore_errors=True)
        if created:
            shutil.rmtree(out, ignore_errors=True)
        if isinstance(exc, OSError):
            raise InputError(f"cannot write the analysis: {exc.strerror or exc}",
                             file=str(out), key="-o") from None
        raise
    rep.out_dir = str(out)
    return rep


def _clustering_section(W: _Writer, lg: Log, rep: AnalysisReport, CP: Any) -> None:
    """The clustering figures a log supports (prototypes, validity by trial and by c)."""
    if lg.has("cluster"):
        sec = "Situations (clustering)"
        try:
            ct = R.clustering_trials(lg)
        except _EXPECTED as exc:
            rep.skipped.append(f"clustering figures: {exc}")
            ct = None
        try:
            spec = lg.sensor  # any beam layout: the sensor's own bearings and range
        except InputError as exc:
            rep.skipped.append(f"prototypes.png: {exc}")
            spec = None
        if spec is not None and lg.has("cluster/state/centers"):
            W.figure(sec, "prototypes.png",
                     f"Cluster prototypes (situations) as polar plots of the {spec.dim} "
                     f"'{spec.name}' ranges (Fig. 5.2)",
                     lambda: CP.plot_prototypes(
                         np.asarray(lg.interpreter_state()["centers"]), spec.angles_deg,
                         max_range=spec.max_range,
                         labels=R.situation_labels(lg, numbered=False)))
        # J_m is in the squared units of the clustered features (see the fcm plugin's transform)
        transform = str(lg.stage("cluster").get("transform", "range"))
        units = {"log": "(log m)", "inverse": "(1/m)"}.get(transform, "m")
        if ct is not None:
            W.figure(sec, "measures_by_trial.png",
                     f"Validity measures of the {ct.n_trials} FCM trials, chosen trial "
                     f"{ct.chosen} marked (Fig. 5.1)",
                     lambda: CP.plot_measures_by_trial(ct, units=units))
        st = lg.stage("cluster")
        if "auto_c" in st and "auto_min_card" in st:
            W.figure(sec, "auto_c.png",
                     f'How c = "auto" chose c = {int(st["auto_c"])}: the minimum cardinality '
                     "and R_f of the sweep over c (the rule in plugins/fcm_interpreter.py)",
                     lambda: CP.plot_auto_c(
                         np.asarray(st["auto_cs"]), np.asarray(st["auto_min_card"]),
                         np.asarray(st["auto_rf"]), int(st["auto_c"]),
                         plateau=float(st.get("auto_plateau", np.nan)),
                         knee=float(st.get("auto_knee", np.nan)),
                         rule=str(st.get("auto_rule", "cardinality"))))
        sw = R.sweep_result(lg)
        if sw is not None:
            W.figure(sec, "measures_by_c.png",
                     "Validity of the chosen partition against the number of clusters c "
                     "(Fig. 4.5)", lambda: CP.plot_measures_by_c(sw, units=units))
        else:
            rep.skipped.append("measures_by_c.png: the log has no sweep over c "
                               "(set [interpreter] sweep = [2, 3, ...] to record one)")



def _spaces_section(W: _Writer, lg: Log, rep: AnalysisReport, CP: Any) -> None:
    """Every situation space of its own: what it is, who reads it, its prototypes."""
    sec = "Situation spaces"
    W.table(sec, "spaces", "Each behaviour's (and the arbiter's) own situations: interpreter, "
            "number, the readings seen, where they came from, who reads them",
            lambda: R.spaces_table(lg))
    spec = lg.sensor
    for name in lg.space_names():
        def prototypes(name: str = name) -> Any:
            sp = lg.space(name)
            view = [int(v) for v in np.asarray(sp["view"])]
            return CP.plot_prototypes(np.asarray(sp["state"]["centers"]),
                                      spec.angles_deg[view], max_range=spec.max_range,
                                      labels=R.situation_labels(lg, numbered=False, space=name))
        W.figure(sec, f"prototypes_{name}.png", f"Prototypes of space '{name}' as polar plots "
                 f"of the readings it sees", prototypes)


def _learning_section(W: _Writer, lg: Log, rep: AnalysisReport, trials: Any, idx: list[int],
                      get: Any, window: int, path_iterations: int, radius: float,
                      LP: Any) -> None:
    """The tables and figures of all trials, then those of the chosen trials."""
    sec = "Learning (all trials)"
    W.table(sec, "convergence", "Convergence and quality of every trial (Table 5.9)",
            lambda: R.convergence_table(lg))

    W.table(sec, "rule_bases", "Learned action per situation in every trial, and the most "
            "frequent one (Tables A.2/A.3)",
            lambda: R.rule_bases_across_trials(lg, read=get))
    first = get(idx[0])
    for lb, pol in first.policies.items():  # behaviours over a space of their own
        space = R.space_of(first, lb)
        if space == "default" or lb == "arbiter":
            continue
        out = "heading" if "heading" in pol.outputs else next(iter(pol.outputs))
        W.table(sec, f"rule_bases_{lb}", f"Learned {out} of '{lb}' per situation of its own "
                f"space '{space}' in every trial, and the most frequent one",
                lambda lb=lb, out=out: R.rule_bases_across_trials(lg, lb, out, read=get))
    if "arbitration/context_visits" in first.behaviours.get("arbiter", {}):
        W.table(sec, "contexts", "The learning arbiter's contexts: visits, updates and "
                "convergence per context over the trials", lambda: R.contexts_table(lg, read=get))

    def curves() -> Any:
        rewards, conv = {}, {}
        for k in idx:
            tr = get(k)
            lab = _reward_label(tr)
            rewards[k] = tr.arrays[f"reward/{lab}"]
            conv[k] = R.convergence_iteration(tr)
        return LP.plot_learning_curves(rewards, conv, window,
                                       title=f"Mean reward per {window} iterations, "
                                       f"{len(idx)} trials")

    W.figure(sec, "learning_curves.png", f"Mean reward per {window} iterations of every "
             "trial and their mean; dots = convergence", curves)

    if trials is None:
        rt = R.representative_trial(lg)
        chosen = [rt] if rt is not None else []
    elif trials == "all":
        chosen = idx
    else:
        chosen = [int(k) for k in trials]  # (checked against the log by analyse)
    rep.trials = chosen
    worlds = R.parsed_worlds(lg)
    if get(idx[0]).situations:
        _situation_figures(W, lg, {k: get(k) for k in idx}, chosen, worlds, radius)
    for k in chosen:
        _trial_figures(W, lg, get(k), worlds, window, path_iterations, radius, LP)


def _plugin_sections(W: _Writer, lg: Log, trials: dict[int, TrialLog]) -> None:
    """A section per plugin (and per behaviour) that logged per-trial data: what it logged,
    its per-trial scalars, a figure of each per-iteration series
    (:mod:`sitframe.analysis.plugin_data`)."""
    from sitframe.analysis import plugin_data as PD  # matplotlib: start-up time

    stems: set[str] = set()
    for j, owner in enumerate(PD.owners(lg, trials)):
        sec = owner.title
        stem = f"{owner.kind[:-1]}_{_safe(owner.name)}"
        stem = stem if stem not in stems else f"{stem}_{j}"  # (two names alike as files)
        stems.add(stem)
        W.table(sec, f"{stem}_logged", f"What {owner.kind[:-1]} '{owner.name}' logged, key by "
                "key", lambda o=owner: PD.inventory(o, trials))
        if (t := PD.scalar_table(owner, trials)) is not None:
            W.table(sec, f"{stem}_scalars", f"Per-trial scalars of {owner.kind[:-1]} "
                    f"'{owner.name}' (columns {owner.kind}.{owner.name}.<key> of the summary "
                    "table: sitframe export, compare)", lambda t=t: t)
        for i, (key, values) in enumerate(PD.series(owner, trials).items()):
            what = f"{owner.kind[:-1]} '{owner.name}': {key}"
            W.figure(sec, f"{stem}_series{i}_{_safe(key)}.png",
                     f"Per-iteration series {key} of {owner.kind[:-1]} '{owner.name}'",
                     lambda k=key, v=values, w=what: PD.plot_series(w, k, v))


def _safe(name: str) -> str:
    """``name`` as part of a file name."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name).strip("_") or "_"


def _reward_label(tr: TrialLog) -> str:
    labels = [k.split("/", 1)[1] for k in tr.arrays if k.startswith("reward/")]
    if not labels:
        raise KeyError(f"trial {tr.index} logged no reward")
    try:
        lab = R.learned_output(tr)[0]
    except InputError:
        return labels[0]
    return lab if lab in labels else labels[0]


def _room_at(tr: TrialLog, s: int, e: int) -> tuple[str, int]:
    """The room iteration ``s`` of a trial ran in and the end (at most ``e``) of its stay
    there: a trial over rooms (``room``, ``learn/rooms``) moves between rooms, any other
    runs in its world."""
    room = tr.arrays.get("room")
    names = tr.episodes.get("learn/rooms")
    if room is None or names is None or s >= len(room):
        return tr.world, e
    names = json.loads(names) if isinstance(names, str) else [str(n) for n in names]
    there = np.asarray(room[s:e]) == room[s]
    stop = s + (int(np.argmin(there)) if not there.all() else len(there))
    return names[int(room[s])], stop


def _trial_figures(W: _Writer, lg: Log, tr: TrialLog, worlds: dict[str, Any], window: int,
                   path_iterations: int, radius: float, LP: Any) -> None:
    k = tr.index
    sec = f"Trial {k}"
    conv = R.convergence_iteration(tr)
    L = int(np.asarray(tr.arrays["collision"]).size)
    state = f"converged at iteration {conv}" if conv is not None else "not converged"

    def exploration() -> Any:
        lab, out = R.learned_output(tr)
        counts = R.exploration_counts(tr, lab, out)
        singles = tr.learned_policy(lab).outputs[out].actions
        # (evolving situations: the rows alive at the end or ever dominant, not every slot)
        shown, words, _notes = R.trial_situations(lg, tr, counts.shape[0], R.space_of(tr, lab))
        named = dict(zip(shown, words, strict=True))
        rows = sorted(set(shown) | set(np.flatnonzero(counts.sum(axis=1)).tolist()))
        labels = [f"S{i + 1}: {named[i]}" if named.get(i) else
                  f"S{i + 1}" + ("" if i in named else " (merged or pruned)") for i in rows]
        return LP.plot_exploration(counts[rows], labels,
                                   singles, action_unit="deg" if out == "heading" else "",
                                   title=f"Trial {k}: situation-action pairs over {L} "
                                   "iterations")

    W.figure(sec, f"exploration_trial{k}.png",
             f"Exploration: how often each (dominant situation, executed action) pair "
             f"occurred in trial {k} (Fig. 5.4)", exploration)
    W.figure(sec, f"collision_intervals_trial{k}.png",
             f"Iterations between collisions in trial {k}, {state} (Fig. 5.5)",
             lambda: LP.plot_collision_intervals(
                 R.collision_intervals(tr.arrays["collision"]), conv,
                 title=f"Trial {k}: {int(np.sum(tr.arrays['collision']))} collisions in "
                 f"{L} iterations"))

    def reward() -> Any:
        lab = _reward_label(tr)
        return LP.plot_reward_per_window(tr.arrays[f"reward/{lab}"], window, conv,
                                         title=f"Trial {k}: mean '{lab}' reward per {window} "
                                         "iterations", reward_label="Mean reward")

    W.figure(sec, f"reward_trial{k}.png",
             f"Mean reward per {window} iterations in trial {k}, {state} (Fig. 5.7)", reward)

    s = conv if conv is not None else max(0, L - path_iterations)
    e = min(L, s + path_iterations)
    room, e = _room_at(tr, s, e)
    world = worlds.get(room)
    if world is not None and "pose" in tr.arrays:
        what = "after convergence" if conv is not None else "at the end (not converged)"
        W.figure(sec, f"trajectory_trial{k}.png",
                 f"Learning path of trial {k} in '{room}', iterations {s}-{e} {what}; "
                 "crosses = collisions (Fig. 5.10)",
                 lambda: LP.plot_trajectory(
                     world, tr.arrays["pose"], collision=tr.arrays.get("collision"),
                     contact=tr.arrays.get("contact"), start=s, stop=e, robot_radius=radius,
                     first=tr.episodes.get("learn/first_iteration",
                                           tr.episodes.get("first_iteration")),
                     goals=tr.episodes.get("learn/goal", tr.episodes.get("goal")),
                     title=f"Trial {k}, {room}, it. {s}–{e}: {_count(tr, s, e)} coll."))
    else:
        W.r.skipped.append(f"trajectory_trial{k}.png: world '{room}' not in the log")
    eps = R.evaluation_episodes(tr)
    if eps:
        cov = {w: float(tr.summary.get(summary_key("eval", w, "coverage"), np.nan)) for w in eps}
        missing = [w for w in eps if w not in worlds]
        if missing:
            W.r.skipped.append(f"evaluation_trial{k}.png: worlds {missing} not in the log")
        W.figure(sec, f"evaluation_trial{k}.png",
                 f"Evaluation paths of trial {k}'s frozen rule base, first {path_iterations} "
                 "iterations per world; crosses = collisions (Fig. 5.11)",
                 lambda: LP.plot_evaluation_paths(
                     worlds, eps, stop=path_iterations, robot_radius=radius, coverage=cov,
                     title=f"Trial {k}: evaluation of the frozen rule base"))
    W.table(sec, f"lookup_table_trial{k}", f"Lookup table Q of trial {k} (Table 5.4)",
            lambda: R.lookup_table(lg, tr))
    W.table(sec, f"rule_base_trial{k}", f"Learned rule base of trial {k} with max Q per "
            "situation (Tables 5.6, 5.7)", lambda: R.rule_base_table(lg, tr))


def _situation_figures(W: _Writer, lg: Log, trials: dict[int, TrialLog], chosen: list[int],
                       worlds: dict[str, Any], radius: float) -> None:
    """Evolving situations: their number against iterations, where they were made, and the
    final prototypes of the chosen trials."""
    from sitframe.analysis import clustering_plots as CP  # matplotlib: start-up time
    from sitframe.analysis import situation_plots as SP  # matplotlib: start-up time

    sec = "Evolving situations"
    start = len(np.asarray(lg.interpreter_state().get("ids", [])))
    finals = [int(t.situations.get("count", 0)) for t in trials.values()]
    W.figure(sec, "situation_counts.png",
             f"Number of situations against iterations, every trial (final: median "
             f"{np.median(finals):g}, range {min(finals)}-{max(finals)})",
             lambda: SP.plot_situation_counts(SP.counts_of(trials, start),
                                              f"Situations during learning, {len(trials)} "
                                              "trials"))
    world = worlds.get(next(iter(trials.values())).world)
    if world is not None:
        W.figure(sec, "situation_events.png",
                 "Where the robot was when situations were created, split, merged or pruned "
                 "(all trials)",
                 lambda: SP.plot_event_map(world, {k: t.situations_part("events")
                                                  for k, t in trials.items()},
                                           "Situation events in the learning room",
                                           robot_radius=radius))
    spec = lg.sensor
    for k in chosen:
        state = trials[k].situations_part("state")
        ids = np.asarray(state.get("ids", []), dtype=int)
        if ids.size:
            W.figure(sec, f"final_prototypes_trial{k}.png",
                     f"Final situations of trial {k}: prototypes (ids as in the log)",
                     lambda s=state, i=ids: CP.plot_prototypes(
                         np.asarray(s["centers"]), spec.angles_deg, max_range=spec.max_range,
                         labels=[f"id {j}, {w}" for j, w in zip(i, describe_prototypes(
                             np.asarray(s["centers"]), spec.angles_deg), strict=True)]))


def _count(tr: TrialLog, s: int, e: int) -> int:
    return int(np.sum(np.asarray(tr.arrays["collision"])[s:e]))


def _write_index(rep: AnalysisReport, lg: Log) -> None:
    a = lg.attrs
    lines = [f"# Analysis of `{os.path.basename(lg.path)}`", "",
             "Open [index.html](index.html) for the same figures and tables on one page "
             "with an interactive replay of every trial.", "",
             f"- log: `{lg.path}`",
             f"- experiment: {a.get('name', '?')}, created {a.get('created', '?')}, "
             f"seed {a.get('seed', '?')}",
             f"- status: **{lg.status}**",
             f"- finished trials: {len(lg.trial_indices())}"
             + (f" of {a['n_trials']}" if "n_trials" in a else "")]
    if rep.trials:
        lines.append(f"- per-trial figures for trial(s) {', '.join(map(str, rep.trials))}"
                     " (default: the converged trial with the median convergence iteration, "
                     "else trial 0; `--trial K` or `--all-trials` for others)")
    lines.append("")
    if rep.problems:
        lines += ["## Incomplete log", "",
                  "This log is incomplete; everything below is computed from what it holds.", ""]
        lines += [f"- {p}" for p in rep.problems] + [""]
    for sec, files in groupby(rep.files, key=lambda f: f[0]):
        lines += ["", f"## {sec}", ""] + [f"- [{n}]({n}) — {c}" for _s, n, c in files]
    if rep.skipped:
        lines += ["", "## Not produced", ""] + [f"- {s}" for s in rep.skipped]
    lines += ["", f"Written by `sitframe analyse` in {rep.seconds:.1f} s.", ""]
    with open(rep.index, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))
