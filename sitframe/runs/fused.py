"""The compiled learning trial: which trials run it, and how their state goes in and out.

A trial runs compiled (:func:`sitframe.runs.fused_kernels.run`: a hundred iterations per call
from Python) when every component of its step is a built-in the kernel reproduces and nothing
has to see each iteration from Python:

* its sensor, interpreter, behaviour, arbiter and reward answer ``_fused()``: the built-in
  ``pioneer-sonar`` (or laser) without noise or dropout, ``fcm`` situations, one ``fuzzy-q``
  behaviour with a heading output and optionally a speed output (at most one of them
  learned) and neither replay nor per-group convergence, the ``single`` arbiter, and the
  ``obstacle-avoidance`` reward without ``progress``, the ``wall-following`` or the
  ``speed`` one. A plugin of one's own answers nothing, and nor does a subclass
  of a built-in that overrides a method of the step;
* the loop has nothing else to do between iterations (:func:`sitframe.runs.loop.simulate`
  decides): no plugin implements ``sitframe_step`` (``sitframe_progress`` follows a trial
  without it), no evaluation protocol may end it early, its situations do not evolve, it has
  one situation space and no candidates. A chain of rooms (``experiment.rooms``) is fine;
* the compiled code is there (numba; neither ``SITFRAME_NUMBA`` nor ``SITFRAME_FUSED`` is
  ``0``), the C library's sines and cosines are numpy's (:func:`sitframe.sim.kernels.fused`),
  numpy hands out its own loops (:mod:`sitframe.sim.numpy_loops`), and a check of this
  trial's memberships, controller output, soft-max draws and dot product against the
  Python components' own finds the same bits (:func:`_agrees`).

Otherwise the trial runs the Python loop. The log is the same either way
(``tests/test_fused.py`` runs both, and the preset digests do not change). A step that touches
a wall is stepped by ``step_robot`` in Python between two calls of the kernel.

:func:`prepare` answers a :class:`Fused` or, as a string, why the trial runs the Python
loop; ``SITFRAME_FUSED=0`` makes every trial run it.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from sitframe.learning.fuzzy_q import FuzzyQLearner, softmax_choice
from sitframe.sim import numba_cache, numpy_loops
from sitframe.sim.kernels import contact, kernels, load
from sitframe.sim.kernels import fused as fused_trig
from sitframe.sim.robot import Command, _times, packed_params, step_robot

__all__ = ["EVERY", "MIN_ITERATIONS", "Fused", "prepare", "run", "wanted"]

#: Iterations per call of the kernel (and between two ``sitframe_progress`` calls).
EVERY = 100
#: A trial this long loads the compiled kernels for itself (shorter ones use them once loaded).
MIN_ITERATIONS = 500
_POWER = {1.0: 1, -1.0: 2, 0.0: 3, 0.5: 4, 2.0: 5}  # (fused_kernels.POW_*: numpy's fast powers)


#: Whether this process said that the trial kernel compiles in the background.
_TOLD: list[bool] = []


def _mode() -> str:
    """``SITFRAME_FUSED``: ``0`` (never compiled), ``wait`` (compile the trial kernel in
    this process when the cache lacks it) or anything else (the default, ``1``: compiled once
    the kernel is cached, compiled in the background when it is not)."""
    return os.environ.get("SITFRAME_FUSED", "1").strip().lower()


def wanted() -> bool:
    """Whether trials may run compiled (``SITFRAME_FUSED`` is not ``0``)."""
    return _mode() != "0"


@dataclass
class Fused:
    """What the kernel needs of a trial's components, and the learner to write back to."""

    kernels: ModuleType
    loops: numpy_loops.Loops
    rays: np.ndarray
    centers: np.ndarray
    heading: Any  # the behaviour's heading controller (a SituationFCS)
    speed: Any  # its speed controller, or None (the run's default speed)
    learner: FuzzyQLearner | None
    learned: str | None  # the output the learner learns ("heading" or "speed")
    fp: np.ndarray
    ip: np.ndarray
    times: np.ndarray
    rp: np.ndarray
    rw: np.ndarray
    side: np.ndarray
    sines: np.ndarray

    def call_args(self) -> tuple[Any, ...]:
        """The loops' pointers, in :func:`sitframe.runs.fused_kernels.run`'s order."""
        lp = self.loops
        return lp.log, lp.power, lp.exp, lp.ddot

    def output(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """An output's singletons (A,) and the one-hot table (c, A) of its rules, as the
        kernel takes them (the speed's, without a speed output, are empty)."""
        fcs = self.speed if name == "speed" else self.heading
        c = self.centers.shape[0]
        if fcs is None:
            return np.zeros(1), np.zeros((c, 1))
        singles = np.array(fcs.singletons, dtype=np.float64)
        onehot = np.zeros((c, singles.size))
        onehot[np.arange(c), np.asarray(fcs.rule_actions, dtype=np.int64)] = 1.0
        return singles, onehot


def _specs(parts: Any, learning: bool) -> dict[str, dict[str, Any]] | str:
    """Each component's ``_fused()`` answer by role (``sensor``, ``interpreter``,
    ``arbiter``, ``behaviour``, ``reward``), or which component has none."""
    (label, (beh, rew)), = parts.behaviours.items()
    comps = {"sensor": ("sensor", parts.sensor), "interpreter": ("interpreter", parts.interp),
             "arbiter": ("arbiter", parts.arbiter), "behaviour": (f"behaviours.{label}", beh)}
    if learning:
        comps["reward"] = (f"behaviours.{label}.reward", rew)
    out = {}
    for role, (key, comp) in comps.items():
        f = getattr(comp, "_fused", None)
        got = f() if callable(f) else None
        if got is None:
            return f"{key} ({type(comp).__name__}) has no compiled form"
        out[role] = got
    return out


def _compiled() -> ModuleType | str:
    """The trial kernel's module (loaded from the cache, or compiled), or why there is none.

    When the cache lacks it (the first run after an install or upgrade), a process of its own
    compiles it (:func:`sitframe.sim.numba_cache.compile_elsewhere`) while this one's trials
    run the Python loop, which gives the same bits; the trials after it is cached run
    compiled. ``SITFRAME_FUSED=wait`` compiles it here instead, before the trial.
    """
    if kernels() is None or fused_trig() is None:
        return "the compiled kernels are not loaded, or their sines differ from numpy's"
    if "sitframe.runs.fused_kernels" not in sys.modules and numba_cache.configure():
        import sitframe.sim.kernels_numba as base  # (loaded: kernels() is not None)

        here = Path(__file__).with_name("fused_kernels.py")
        numba_cache.drop_stale(here, Path(base.__file__), Path(numpy_loops.__file__))
        busy = None if _mode() == "wait" else \
            numba_cache.compile_elsewhere("sitframe.runs.fused_kernels", here)
        if busy is not None:
            if not _TOLD:
                numba_cache.announce_compilation(here, background=True)
                _TOLD.append(True)
            return f"the compiled trial: {busy}"
        numba_cache.announce_compilation(here)
    from sitframe.runs import fused_kernels  # (numba's import: only a process that simulates)

    return fused_kernels


def prepare(res: Any, spec: Any, parts: Any) -> Fused | str:
    """The compiled form of a trial whose loop has nothing else to do (the module docstring),
    or why it runs the Python loop."""
    if not wanted():
        return "SITFRAME_FUSED=0"
    if len(parts.behaviours) != 1:
        return "the kernel runs one behaviour"
    learning = bool(parts.learners)
    specs = _specs(parts, learning)
    if isinstance(specs, str):
        return specs
    if kernels() is None and spec.iterations >= MIN_ITERATIONS:
        load()
    fk = _compiled()
    lp = numpy_loops.loops()
    if isinstance(fk, str) or isinstance(lp, str):
        return fk if isinstance(fk, str) else lp
    sen, itp, beh = specs["sensor"], specs["interpreter"], specs["behaviour"]
    lr, robot = beh["learner"], res.robot
    prm = lr.params if lr is not None else None
    rw = specs.get("reward", {"kind": "obstacle-avoidance", "params": [0.0, 0.0, 0.0]})
    kinds = list(fk.REWARDS)
    if rw["kind"] not in kinds or len(rw["params"]) != len(fk.REWARDS[rw["kind"]]):
        return f"the kernel computes no reward '{rw['kind']}'"
    learned = (0.0,) * 7 if prm is None else (
        prm.alpha, prm.gamma, prm.activation, prm.temperature, prm.temperature_decay,
        prm.temperature_min, prm.alpha_visits)
    rules = (0,) * 8 if prm is None else (
        prm.b, prm.p, prm.min_updates, prm.update == "thesis", prm.terminal_on_collision,
        prm.tie_break == "centre", prm.temperature_mode == "relative",
        prm.temperature_decay != 1.0)
    fp = np.array([sen["max_range"], sen["radius"], itp["offset"], itp["p"], itp["floor"],
                   *learned, res.config.experiment.default_speed], dtype=np.float64)
    if fp.size != len(fk.FP):  # (the kernel reads them by position)
        raise AssertionError(f"fused: {fp.size} float parameters, the kernel reads {fk.FP}")
    ip = np.array([sen["rays_per_beam"], itp["transform"], _POWER.get(itp["p"], 0),
                   lr is not None, learning, *rules, contact() is not None,
                   kinds.index(rw["kind"]), beh["speed"] is not None,
                   beh["learned"] == "speed", True], dtype=np.int64)  # (clip: no noise)
    if ip.size != len(fk.IP):
        raise AssertionError(f"fused: {ip.size} integer parameters, the kernel reads {fk.IP}")
    # (every array C-contiguous and writable but the world's segments and the substep times,
    # read-only: the types fused_kernels._warm compiles for)
    fz = Fused(fk, lp, np.array(sen["rays"], dtype=np.float64),
               np.array(itp["centers"], dtype=np.float64), beh["heading"], beh["speed"], lr,
               beh["learned"], fp, ip,
               _times(robot.control_period_s, robot.substep_s), packed_params(robot),
               np.array(rw["params"], dtype=np.float64),
               np.array(rw.get("side", [0]), dtype=np.int64),
               np.array(rw.get("sines", [0.0]), dtype=np.float64))
    why = _agrees(fz, parts)
    return why if why else fz


def _agrees(fz: Fused, parts: Any) -> str:
    """'' when the kernel's memberships, controller outputs, soft-max draws and value of the
    next situation equal the Python components' on probes (fixed, not the trial's draws);
    else what differed."""
    probe = np.random.default_rng(20261207)
    d = fz.rays.size // int(fz.ip[0])
    readings = np.vstack([probe.uniform(0.0, fz.fp[0], (12, d)), np.full((1, d), fz.fp[0]),
                          probe.uniform(0.0, 0.3, (3, d))])
    lr = fz.learner
    prm = lr.params if lr is not None else None
    tau = prm.temperature if prm is not None else 1.0
    relative = prm is None or prm.temperature_mode == "relative"
    for name, fcs in (("heading", fz.heading), ("speed", fz.speed)):
        if fcs is None:
            continue
        singles, onehot = fz.output(name)
        q = probe.normal(250.0, 30.0, (fz.centers.shape[0], singles.size))
        got, outs, mine, v = fz.kernels.probe(readings, fz.centers, fz.fp, fz.ip, fz.loops,
                                              onehot, singles, q, float(tau), relative,
                                              np.random.default_rng(7))
        for r, u, o in zip(readings, got, outs, strict=True):
            ref = parts.interp.memberships(r)
            if not np.array_equal(ref, u):
                return "the compiled memberships differ from the interpreter's"
            if fcs.output(ref) != o:
                return f"the compiled {name} output differs from the behaviour's"
        if fz.learned == name and prm is not None and (
                not np.array_equal(softmax_choice(q, prm, np.random.default_rng(7), tau), mine)
                or v != float(got[0] @ np.maximum.reduce(q, axis=1))):
            return "the compiled soft-max or value of the next situation differs from numpy's"
    return ""


def run(fz: Fused, res: Any, spec: Any, rec: Any, env: Any, chain: Any,
        progress: Callable[[int, int], None] | None) -> int:
    """Run the trial compiled, recording into ``rec``; returns its number of iterations.

    ``env`` gives the start pose, world and Generator; ``chain`` is its
    :class:`~sitframe.runs.loop.RoomEpisodes` or ``None``; ``progress(trial, iterations)``
    is told after every :data:`EVERY` iterations (the caller tells the rest).
    """
    L, lr, fk = spec.iterations, fz.learner, fz.kernels
    learned = fz.speed if fz.learned == "speed" else fz.heading
    c, a = fz.centers.shape[0], np.asarray(learned.singletons).size
    learn = _LearnerState(lr, np.asarray(learned.rule_actions), c, a, L)
    (heads, onehot), (speeds, onehot_s) = fz.output("heading"), fz.output("speed")
    if fz.learned == "speed":  # (the learner changes its output's table in place)
        onehot_s = learn.onehot
    else:
        onehot = learn.onehot
    state = np.array([learn.converged, learn.stable, learn.since, learn.changes, 1, 0, 0],
                     dtype=np.int64)
    carry = np.zeros(5)
    carry[:3] = env.start
    reading, u, world = np.empty(rec.reading.shape[1]), np.empty(c), env.world
    none2, rp = np.full(2, np.nan), fz.rp
    rewards = rec.rewards[:, 0] if rec.rewards.shape[1] else np.empty(L)  # (none: unwritten)
    t = 0
    while t < L:
        t1 = min(L, (t // EVERY + 1) * EVERY)
        if chain is not None:
            t1 = min(t1, chain.first[-1] + chain.episode)
        snaps = (np.empty(t1 - t, np.int64), np.empty((t1 - t, c), np.int64),
                 np.empty((t1 - t, c), np.int64), np.empty((t1 - t, c, a)))
        state[6] = 0
        after, hit, contact, resume = carry[:3], False, none2, False
        seg = world.segment_set.packed
        while fk.run(t1, resume, after, hit, contact, seg, fz.times, rp, fz.rw, fz.side,
                     fz.sines,
                     fz.rays, fz.centers, heads, onehot, speeds, onehot_s, learn.q, learn.updates,
                     learn.visits, learn.rule_base, learn.greedy, learn.rules_it, fz.fp, fz.ip,
                     state, carry, reading, u, env.rng, *fz.call_args(), rec.pose,
                     rec.reading, rec.memberships, rec.command, rec.nearest, rec.collision,
                     rec.contact, rewards,
                     *snaps) == fk.NEED_STEP:
            out = step_robot(world, carry[:3].copy(), Command(float(carry[3]), float(carry[4])),
                             res.robot, env.rng)
            after, hit, contact, resume = np.array(out.pose), bool(out.collided), \
                np.array(out.contact_xy), True
        learn.snapshots(snaps, int(state[6]))
        t = t1
        if progress is not None and t % EVERY == 0:
            progress(spec.index, EVERY)
        if chain is not None and chain.over(None, t, L):
            start, _goal, world = next(chain.pairs)
            carry[:3] = start
            state[4] = 1
    rec.pose[L] = carry[:3]
    rec.weights[:] = 1.0
    rec.proposals[:, 0] = rec.command[:L, 0]
    rec.proposals[:, 1] = np.nan if fz.speed is None else rec.command[:L, 1]
    learn.write_back(state, learned)
    return L


class _LearnerState:
    """A learner's arrays as the kernel takes them (or stand-ins when the rules are fixed),
    and their return to the :class:`~sitframe.FuzzyQLearner` after the trial."""

    def __init__(self, lr: FuzzyQLearner | None, rules: np.ndarray, c: int, a: int,
                 iterations: int) -> None:
        self.lr = lr
        self.rule_base = rules.astype(np.int64)
        self.onehot = np.zeros((c, a))
        self.onehot[np.arange(c), self.rule_base] = 1.0
        self.visits = np.zeros((c, a), dtype=np.int64)
        if lr is None:
            self.q, self.updates, self.greedy = np.zeros((c, a)), np.zeros(c, np.int64), \
                self.rule_base.copy()
            self.rules_it = np.zeros((1, c), dtype=np.int8)
            self.converged, self.stable, self.since, self.changes = -1, 0, 0, 0
            return
        self.q, self.updates, self.rules_it = lr.q, lr.updates, lr.rules_per_iteration
        self.greedy = np.asarray(lr.greedy, dtype=np.int64).copy()
        for (i, k), n in lr._visits.items():
            self.visits[i, k] = n
        self.converged = -1 if lr.converged_at is None else lr.converged_at
        self.stable, self.since, self.changes = lr.stable_changes, lr.since_change, lr.n_changes

    def snapshots(self, snaps: tuple[np.ndarray, ...], k: int) -> None:
        """Append the ``k`` rule-base changes of a call to the learner's snapshots."""
        if self.lr is None or not k:
            return
        it, rules, greedy, q = snaps
        self.lr._snap_iter.extend(it[:k].tolist())
        self.lr._snap_rules.extend(rules[:k])
        self.lr._snap_greedy.extend(greedy[:k])
        self.lr._snap_q.extend(q[:k])

    def write_back(self, state: np.ndarray, fcs: Any) -> None:
        """The learner's scalars, rule bases and learning-rate counts after the trial."""
        lr = self.lr
        if lr is None:
            return
        lr.converged_at = None if state[0] < 0 else int(state[0])
        lr.stable_changes, lr.since_change, lr.n_changes = (int(v) for v in state[1:4])
        lr.rule_base, lr.greedy = self.rule_base.copy(), self.greedy.copy()
        lr._vmax = None
        lr._visits = {(int(i), int(k)): int(n) for (i, k), n in np.ndenumerate(self.visits)
                      if n}
        fcs.set_rules(lr.rule_base)
