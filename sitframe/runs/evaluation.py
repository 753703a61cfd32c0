"""Evaluate a log's learned policies in any world, and print its rule bases.

``evaluate_log`` runs one trial's frozen policies in a world file of the user's
choice (one run, or a batch of the run's evaluation protocol's episodes); ``rule_base_table``
is the table ``sitframe run`` prints.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from typing import Any

import numpy as np

from sitframe.contract.checks import BoundaryError, call, check_data
from sitframe.contract.config import (
    DEFAULT_PROTOCOL,
    META_KEYS,
    SELECTION_DEFAULTS,
    Config,
    load_config,
    validate_config,
)
from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.records import LearnedPolicy, summary_key
from sitframe.contract.resolve import Resolved
from sitframe.errors import InputError, PluginFault, located_in
from sitframe.logs.policies import (
    BEST_TRIAL_RULE,
    best_of,
    check_logged_policy,
    check_state,
    logged_policy,
    plugins_of,
)
from sitframe.logs.reader import Log, open_log
from sitframe.runs.loop import (
    EVAL_KEYS,
    STAGE_BATCH,
    STAGE_EVAL,
    TrialSpec,
    batch_scores,
    simulate,
    stage_seed,
)
from sitframe.situations.labels import describe_prototypes


def evaluate_log(
    log_path: str,
    *,
    world: str,
    trial: int = 0,
    iterations: int = 1000,
    seed: int = 0,
    plugins_dirs: tuple[str, ...] = (),
    goal_episodes: int = 0,
    arbiter: str | None = None,
    fusion: str = "goal-finding",
    checked: Log | None = None,
    per_episode: bool = False,
) -> dict[str, Any]:
    """Run trial ``trial``'s frozen policies from a log in ``world``.

    Without ``goal_episodes``: one ``iterations``-long run from the world's
    start. Returns ``iterations``, ``collisions``, ``collisions_per_1000``,
    ``distance_m``, ``mean_speed_m_s``, ``coverage``, plus whatever the
    ``metrics(arrays)`` method of each of the log's reward components returns
    (a reward may define one to score its own behaviour, e.g. the
    wall-following reward adds ``wall_band_fraction`` and
    ``wall_distance_rmse_m``). ``arbiter`` replaces the log's arbiter.

    A behaviour that learned nothing but logged ``params/<key>`` trial data (a
    frozen deep-RL policy, ``plugins/sb3_policy.py``: its model file's hash) is
    re-created with those parameters added to its table, so the log is scored
    with the policy that ran; a run with neither a learned policy nor such a
    behaviour cannot be evaluated.

    With ``goal_episodes = N``: N episodes of the run's evaluation protocol
    (one batch, :func:`sitframe.runs.loop.run_batch`; its table's
    ``episodes`` set to N), e.g. random goal episodes
    (``plugins/goal_episodes.py``) in ``world``. If the log's config has a
    protocol (a goal run) it is used; otherwise the behaviours, arbiter and ``[goal]`` table
    come from the ``fusion`` config (a preset name or a TOML path; default the
    ``goal-finding`` preset), whose behaviour with a ``policy_from`` is
    replaced by the log's learned (else frozen) behaviour (its table and its policy), with
    the log's situations. ``arbiter`` names another arbiter (its own
    parameters are kept if the fusion config configures that arbiter, else
    its defaults); a learned arbitration in the log belongs to the arbiter
    that learned it, so another arbiter runs without it, and an arbiter that
    learns (it has ``policy()``) with no learned arbitration of its own in the
    log is an input error, not an untrained run. Returns ``episodes``, ``success_rate``,
    ``collisions_per_episode``, ``collision_free_rate``, ``spl``,
    ``mean_time_s``, ``heading_change_per_m``, ``mean_path_length_m``.

    ``checked``: the log at ``log_path``, already opened and checked (its
    layout and checksums), when several trials of it are evaluated in turn
    (:func:`select_trial`); by default the log is opened and checked here.

    ``per_episode`` (with ``goal_episodes``): also return ``per_episode``, the
    protocol's figures of every episode (one list per key, in episode order:
    ``success``, ``collisions``, ``path_length_m``, ``shortest_m``, ... and
    ``start``, ``goal``), so that two arbiters can be compared pair by pair
    (the pairs depend only on the world and the seed).
    """
    log = checked
    if log is None:
        log = open_log(log_path)
        log.check()
    cfg = validate_config(log.config, file=log_path, pending=True)  # (checked as it resolves)
    tl = log.trial(trial)
    policies = {label: p for label in tl.behaviours
                if (p := logged_policy(tl, label, log_path)) is not None}
    pinned = _pinned(tl.behaviours, cfg)
    if not policies and not pinned:
        raise InputError(f"trial {trial} has no learned policy to evaluate", file=log_path,
                         key="trials")
    for label, params in pinned.items():  # e.g. the model file's hash of a frozen policy
        cfg["behaviours"][label] = {**cfg["behaviours"][label], **params}
    state = _trial_state(log, tl, cfg)
    space_states = log.space_states()  # (situation spaces of their own, as the run fitted them)
    pm = get_plugin_manager(plugins_dirs=plugins_dirs)
    registry = Registry.collect(pm)
    if arbiter is not None:
        registry.get("arbiter", arbiter, key="--arbiter")
    source = log_path
    with plugins_of(log, log_path, plugins_dirs):
        if goal_episodes and Resolved.build(cfg, registry, log_path).protocol_name(
                default=None) is None:
            cfg, policies, source = _fusion_config(cfg, policies, list(pinned), fusion,
                                                   log_path)
        if arbiter is not None:
            params = cfg["arbiter"] if cfg["arbiter"].get("component") == arbiter else {}
            if not params:  # (a learned arbitration belongs to the arbiter that learned it)
                policies.pop("arbiter", None)
            cfg["arbiter"] = {**params, "component": arbiter}
        res = Resolved.build(cfg, registry, source)
    _check_arbitration(res, policies, trial, log_path, arbiter)
    res.world(world, key="--world")
    check_state(res, state, log_path, log.sensor)
    _check_spaces(res, space_states, log_path)
    for label in set(policies) & set(res.config.behaviours):
        check_logged_policy(res, label, policies[label], log_path,
                     f"trials/{trial:04d}/behaviours/{label}")
    # the run's protocol with the episodes asked for, or one frozen run of ``iterations``
    name = res.protocol_name(default=None) if goal_episodes else DEFAULT_PROTOCOL
    if name is None:
        raise InputError("no component names an evaluation_protocol to run episodes of; "
                         "expected a behaviour such as 'goal'", file=source, key="behaviours")
    table = res.protocol_table(name)
    if table is None:
        raise InputError(f"the evaluation protocol '{name}' declares no config table, so "
                         f"{'--goal-episodes' if goal_episodes else '--iterations'} has "
                         "nothing to set", file=source, key="behaviours")
    cfg[table] = {**cfg[table], **({"episodes": goal_episodes} if goal_episodes
                                   else {"iterations": iterations})}
    res = Resolved.build(cfg, registry, source)
    stage = (STAGE_BATCH, 0) if goal_episodes else (STAGE_EVAL, trial)
    with located_in(source):  # (a setting of the log's config found wrong in this world)
        result = simulate(res, TrialSpec(index=trial, seed=stage_seed(seed, *stage), world=world,
                                         iterations=int(res.protocol(name).iterations),
                                         learn=False, interpreter_state=state,
                                         policies=policies, protocol=name,
                                         space_states=space_states))
    out: dict[str, Any] = {"log": log_path, "world": world, "trial": trial}
    if res.config.spaces:  # which situations each component read
        out["spaces"] = {sp.name: {"situations": sp.n_situations, "view": list(sp.view),
                                   "read_by": list(sp.readers)}
                         for sp in res.run.spaces.values()}
    if goal_episodes:
        out = {**out, "arbiter": res.config.arbiter.name, **batch_scores(result)}
        if per_episode:
            out["per_episode"] = {k: np.asarray(v).tolist() for k, v in result.episodes.items()
                                  if isinstance(v, np.ndarray) and k != "first_iteration"}
        return out
    out.update({key: result.summary[key] for key in EVAL_KEYS})
    return {**out, **_reward_metrics(res, result.arrays)}


def _check_spaces(res: Resolved, space_states: dict[str, Any], log_path: str) -> None:
    """Every situation space of the config is in the log and fits its interpreter."""
    for name in res.config.spaces:
        if name not in space_states:
            raise InputError(f"the log has no fitted situations of space '{name}' (its "
                             f"/spaces holds {', '.join(space_states) or 'none'})",
                             file=log_path, key=f"spaces/{name}")
        check_state(res, space_states[name], log_path, space=name)


def _check_arbitration(res: Resolved, policies: dict[str, Any], trial: int, log_path: str,
                       arbiter: str | None) -> None:
    """Refuse to run an arbiter that learns (it has ``policy()``) without an arbitration it
    learned: that would score an untrained arbitration as if it were the log's."""
    if callable(getattr(res.arbiter(), "policy", None)) and "arbiter" not in policies:
        name = res.config.arbiter.name
        raise InputError(f"arbiter '{name}' learns its arbitration, but trial {trial} of the log "
                         f"has no arbitration learned by '{name}' to run; expected an arbiter "
                         "that learns nothing (e.g. cdb, priority) or the log of a run that "
                         f"learned with '{name}'", file=log_path,
                         key="--arbiter" if arbiter is not None else "arbiter")


def _reward_metrics(res: Resolved, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """What the rewards' optional ``metrics(arrays)`` make of an evaluation (a fault in one
    is the reward's, not the log's)."""
    out: dict[str, Any] = {}
    for label, (_beh, reward) in res.behaviours().items():
        metrics = getattr(reward, "metrics", None)
        if metrics is not None:
            o = res.origins[f"behaviours.{label}.reward"]
            try:
                out.update(check_data(call(o, "metrics", metrics, arrays),
                                      "figures of the evaluation"))
            except BoundaryError as exc:
                raise PluginFault(str(exc), where=str(o), method="metrics") from None
    return out


def selection_rule(selection: dict[str, Any]) -> str:
    """:func:`select_trial`'s rule for ``selection``, in words."""
    sel = {**SELECTION_DEFAULTS, **selection}
    return (f"highest {sel['score']} in {sel['episodes']} episodes in '{sel['world']}', "
            f"seed {sel['seed']}")


def select_trial(path: str, selection: dict[str, Any], *,
                 plugins_dirs: tuple[str, ...] = ()) -> int:
    """The trial of log ``path`` whose frozen policies score highest in a short episode run.

    ``policy_from.trial = {world, episodes, score, seed}``. Every trial runs
    the same ``episodes`` episodes (same start/goal pairs: ``seed``) of the
    evaluation protocol in ``world``, exactly as ``sitframe evaluate PATH
    --world W --trial K --goal-episodes N --seed S`` does (a log of a run
    without a protocol, e.g. obstacle avoidance, is fused with goal seeking
    by the ``goal-finding`` preset's CDB); the trial with the highest
    ``score`` (a key of that command's output, default
    ``collision_free_rate``) wins, ties to the lowest index. Choose ``world``
    among the rooms the robot *learns* in, never a test room: a short
    goal-episode run in ``goal-training`` predicts the collision-free rate in
    unseen rooms far better than :func:`best_trial`'s rank sum (docs/results/learned-arbitration.md,
    "Choosing the avoidance rule base"). The result is kept for the process
    (same log file, unchanged, and same selection), so a sweep whose points
    share the selection runs it once.

    Raises
    ------
    InputError
        ``score`` is not a key the protocol reports, or is NaN for a trial.
    """
    sel = {**SELECTION_DEFAULTS, **selection}
    st = os.stat(path)  # (a sweep prepares every point with the same selection: once)
    key = (os.path.realpath(path), st.st_mtime_ns, st.st_size, tuple(sorted(sel.items())),
           plugins_dirs)
    if key not in _SELECTED:
        _SELECTED[key] = _select(path, sel, plugins_dirs)
    return _SELECTED[key]


_SELECTED: dict[tuple[Any, ...], int] = {}


def _select(path: str, sel: dict[str, Any], plugins_dirs: tuple[str, ...]) -> int:
    best, best_score = -1, -math.inf
    log = open_log(path)
    log.check()  # (once, not once per trial)
    for k in log.trial_indices():
        out = evaluate_log(path, world=str(sel["world"]), trial=k, seed=int(sel["seed"]),
                           goal_episodes=int(sel["episodes"]), plugins_dirs=plugins_dirs,
                           checked=log)
        v = out.get(str(sel["score"]))
        if not isinstance(v, (int, float)) or math.isnan(v):
            raise InputError(f"cannot select a trial by '{sel['score']}': the episodes report "
                             f"{'NaN' if isinstance(v, float) else 'no such score'} for trial "
                             f"{k}; expected one of "
                             f"{', '.join(x for x, y in out.items() if isinstance(y, float))}",
                             file=path, key="policy_from.trial.score")
        if v > best_score:
            best, best_score = int(k), float(v)
    return best


def _pinned(behaviours: dict[str, dict[str, Any]], cfg: dict[str, Any]
            ) -> dict[str, dict[str, Any]]:
    """Each behaviour's ``params/<key>`` trial data: parameters it ran with beyond its table
    (a frozen policy's model hash), which re-create the same behaviour."""
    out = {}
    for label, data in behaviours.items():
        params = {k.split("/", 1)[1]: v for k, v in data.items() if k.startswith("params/")}
        if params and label in cfg["behaviours"]:
            out[label] = params
    return out


def _trial_state(log: Log, tl: Any, cfg: dict[str, Any]) -> dict[str, Any]:
    """The situations trial ``tl`` of ``log`` ran with: those that evolved in the trial (its
    own final ones), the run's fitted ones, or those of the log it reused (a goal run's)."""
    clusters_from = Config.of(cfg).experiment.clusters_from
    if tl.situations:
        return tl.situations_part("state")
    if log.has("cluster/state") or not clusters_from:
        return log.interpreter_state()
    return open_log(clusters_from).interpreter_state()


def _fusion_config(log_cfg: dict[str, Any], policies: dict[str, LearnedPolicy],
                   frozen: list[str], fusion: str, log_path: str
                   ) -> tuple[dict[str, Any], dict[str, LearnedPolicy], str]:
    """The fusion config with the log's learned behaviour (or, without one, its ``frozen``
    behaviour, e.g. a deep-RL policy) in its ``policy_from`` slot."""
    fcfg, fsource, _base = load_config(fusion)
    slots = [lb for lb, t in fcfg["behaviours"].items() if t.get("policy_from")]
    if not slots:
        raise InputError("no behaviour has a policy_from table to receive the log's learned "
                         "behaviour", file=fsource, key="behaviours")
    slot = slots[0]
    want = fcfg["behaviours"][slot]["policy_from"].get("behaviour", slot)
    sources = [*policies, *(lb for lb in frozen if lb not in policies)]
    src = want if want in sources else sources[0]
    table = {k: v for k, v in log_cfg["behaviours"][src].items()
             if k == "component" or k not in META_KEYS}
    fcfg["behaviours"] = {lb: table if lb == slot else {k: v for k, v in t.items()
                                                        if k != "policy_from"}
                          for lb, t in fcfg["behaviours"].items()}
    for section in ("sensor", "interpreter", "robot"):
        fcfg[section] = log_cfg[section]
    if "spaces" in log_cfg and "space" in table:  # the behaviour reads a space of its own
        fcfg["spaces"] = {table["space"]: log_cfg["spaces"][table["space"]]}
    fcfg["experiment"]["clusters_from"] = ""
    return (validate_config(fcfg, file=fsource, pending=True),
            {slot: policies[src]} if src in policies else {}, fsource)


def format_action(value: float, unit: str) -> str:
    """An action value for a table: ``+30°``, ``0.20 m/s``, or the number and its unit."""
    if unit == "deg":
        return f"{value:+.0f}°"
    if unit == "m/s":
        return f"{value:.2f} m/s"
    return f"{value:.3g} {unit}".rstrip()


def rule_base_table(result: Any, space: str = "default") -> Any:
    """A rich Table of the learned rule bases of a run, one row per situation of ``space``.

    For each learned output of the behaviours (and arbiter) that read ``space``
    (the ``[interpreter]``'s ``"default"``, or a ``[spaces.NAME]``): the action
    most trials chose for the situation and in how many trials (thesis Tables
    A.2/A.3), and the action of the trial that ``policy_from.trial = "best"``
    would pick (:func:`best_trial`: collisions and coverage when evaluated in
    the learning world; trial 0 when there is no such evaluation). Situations
    are described from their prototypes. With evolving situations the rows are the
    best trial's own (those alive at its end): only the fitted situations every trial
    starts from are voted on, by the trials that kept them; a situation a trial made is
    its own (another trial's of that number is another situation) and gets no vote.
    """
    from rich.table import Table

    trials = result.trials
    config = Config.of(result.info.config)
    world = config.experiment.world
    key = summary_key("eval", world, "collisions_per_1000")
    ranked = [t for t in trials if key in t.summary]
    best = trials[0]
    if ranked:
        k = best_of([t.index for t in ranked], [t.summary[key] for t in ranked],
                     [t.summary.get(summary_key("eval", world, "coverage"), 0.0) for t in ranked],
                     [t.summary["collisions_per_1000_after_convergence"] for t in ranked])
        best = next(t for t in ranked if t.index == k)
    why = (f"best trial {best.index}: {BEST_TRIAL_RULE} when evaluated in '{world}'"
           if ranked else f"trial {best.index}: no evaluation in the learning world")
    readers = config.readers(space)
    of_space = f" over space '{space}'" if config.spaces else ""
    table = Table(title=f"learned rule bases of {len(trials)} trials{of_space}",
                  caption=f"most trials = the most frequent action (how many trials); {why}")
    table.add_column("situation", justify="right")
    table.add_column("description")
    outs = [(label, out, o) for label, pol in best.policies.items() if label in readers
            for out, o in pol.outputs.items()]
    for label, out, _o in outs:
        table.add_column(f"{label}.{out}\nmost trials", justify="right")
        table.add_column(f"{label}.{out}\ntrial {best.index}", justify="right")
    if not outs:
        return table
    angles = result.sensor_angles_deg
    if space == "default":
        centers = result.interpreter_state.get("centers")
    else:
        centers = getattr(result, "space_states", {}).get(space, {}).get("centers")
        view = config.spaces[space].view
        if angles is not None and view is not None:
            angles = np.asarray(angles)[list(view)]
    rows: Any = range(outs[0][2].rules.size)
    voters: dict[int, list[Any]] = {}  # evolving: who has situation i (alive at its end)
    if space == "default" and (own := getattr(best, "situations", {}).get("state")):
        seeded = np.shape(centers)[0] if centers is not None and np.ndim(centers) == 2 else 0
        rows, centers = [int(i) for i in own["ids"]], own["centers"]  # the best trial's own
        alive = {t.index: {int(i) for i in t.situations["state"]["ids"]} for t in trials
                 if getattr(t, "situations", {}).get("state")}
        voters = {i: [t for t in trials if i in alive.get(t.index, ())] if i < seeded else []
                  for i in rows}
        table.caption = (f"most trials = the most frequent action of the trials that kept the "
                         f"situation (how many of them); S{seeded + 1} on are situations trial "
                         f"{best.index} made, each trial makes its own: no vote; {why}")
    descs = describe_prototypes(centers, angles) if centers is not None and \
        angles is not None and np.ndim(centers) == 2 and len(angles) == np.shape(centers)[1] \
        else []
    for n, i in enumerate(rows):
        row = [f"S{i + 1}", descs[n] if n < len(descs) else ""]
        for label, out, o in outs:
            row.append(_vote(voters[i] if voters else trials, label, out, o, i))
            row.append(format_action(o.actions[int(o.rules[i])], o.unit))
        table.add_row(*row)
    return table


def _vote(trials: list[Any], label: str, out: str, o: Any, i: int) -> str:
    """The action most of ``trials`` chose for situation ``i`` and in how many (``–``: none
    has the situation)."""
    votes = Counter(int(t.policies[label].outputs[out].rules[i]) for t in trials
                    if label in t.policies)
    if not votes:
        return "–"
    action, count = votes.most_common(1)[0]
    return f"{format_action(o.actions[action], o.unit)} ({count}/{len(trials)})"
