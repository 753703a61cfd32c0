"""The compiled learning trial: which trials run it, and how their state goes in and out.

A trial runs compiled (:func:`sitframe.runs.fused_kernels.run`: a hundred iterations per call
from Python) when every component of its step is a built-in the kernel reproduces and nothing
has to see each iteration from Python:

* its sensor, interpreter, behaviour, arbiter and reward answer ``_fused()``: the built-in
  ``pioneer-sonar`` (or laser) without noise or dropout, ``fcm`` or ``evolving`` situations
  (evolving ones followed by the behaviour alone), one
  ``fuzzy-q`` behaviour with a heading output and optionally a speed output (at most one of
  them learned) and neither replay nor per-group convergence, the ``single`` arbiter, and the
  ``obstacle-avoidance`` reward without ``progress``, the ``wall-following`` or the
  ``speed`` one. A plugin of one's own answers nothing, and nor does a subclass
  of a built-in that overrides a method of the step;
* the loop has nothing else to do between iterations (:func:`sitframe.runs.loop.simulate`
  decides): no plugin implements ``sitframe_step`` (``sitframe_progress`` follows a trial
  without it), no evaluation protocol may end it early (the built-in ``frozen`` protocol's
  runs, which only their length ends, are fine: its ``_fused()`` says so), it has one
  situation space and no candidates. A chain of rooms (``experiment.rooms``) is fine;
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

Evolving situations: the kernel computes the memberships, the coverage streak and the on-line
update of the prototypes itself, and hands Python the iterations whose memberships create a
situation or run the periodic merge, prune and split (the interpreter's own ``memberships``,
a few in a hundred); the events these make are delivered by the trial's tracker between two
calls, after the iteration's learning, as the Python loop delivers them.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from sitframe import scratch
from sitframe.learning.fuzzy_q import FuzzyQLearner, softmax_choice
from sitframe.params import environment
from sitframe.sim import numba_cache, numpy_loops
from sitframe.sim.kernels import contact, kernels, load
from sitframe.sim.kernels import fused as fused_trig
from sitframe.sim.robot import Command, _times, packed_params, step_robot
from sitframe.situations.fcm import row_sq_norms

__all__ = ["EVERY", "MIN_ITERATIONS", "RELEASE", "Fused", "prepare", "run", "wanted"]

#: Iterations per call of the kernel (and between two ``sitframe_progress`` calls).
EVERY = 100
#: Iterations between two releases of the pages of a trial's rows recorded in scratch files
#: (:func:`sitframe.scratch.release_all`): a long trial's memory stays that of this many.
RELEASE = 50 * EVERY
#: A trial this long loads the compiled kernels for itself (shorter ones use them once loaded).
MIN_ITERATIONS = 500
_POWER = {1.0: 1, -1.0: 2, 0.0: 3, 0.5: 4, 2.0: 5}  # (fused_kernels.POW_*: numpy's fast powers)


#: Whether this process said that the trial kernel compiles in the background.
_TOLD: list[bool] = []


def _mode() -> str:
    """``SITFRAME_FUSED``: ``0`` (never compiled), ``wait`` (compile the trial kernel in
    this process when the cache lacks it) or ``1`` (the default: compiled once the kernel is
    cached, compiled in the background when it is not); checked by
    :func:`sitframe.params.environment`."""
    return environment("SITFRAME_FUSED")


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
    ids: np.ndarray  # the ids of ``centers`` (0 .. c - 1 but for evolving situations)
    c: int  # the length of a membership vector (evolving: the capacity)
    situations: Any  # the evolving interpreter, or None (fixed centres)
    track: Any  # the trial's SituationTracker, or None

    def call_args(self) -> tuple[Any, ...]:
        """The loops' pointers, in :func:`sitframe.runs.fused_kernels.run`'s order."""
        lp = self.loops
        return lp.log, lp.power, lp.exp, lp.ddot

    def output(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """An output's singletons (A,) and the one-hot table (c, A) of its rules, as the
        kernel takes them (the speed's, without a speed output, are empty)."""
        fcs = self.speed if name == "speed" else self.heading
        c = self.c
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


def _evolving(itp: dict[str, Any], parts: Any, lr: FuzzyQLearner | None, track: Any
              ) -> tuple[np.ndarray, int, Any] | str:
    """``(ids, c, interpreter)`` of the trial's situations: fixed centres (``interpreter``
    ``None``), or an evolving interpreter followed by the behaviour alone; or why the trial
    runs the Python loop."""
    ev = itp.get("evolving")
    if ev is None:
        c = np.asarray(itp["centers"]).shape[0]
        return np.arange(c, dtype=np.int64), c, None
    if track is not None:
        ((_label, (beh, _rew)),) = parts.behaviours.items()
        followed = [getattr(f, "__self__", None) for _o, f in
                    (*track.followers, *track.error_sources, *track.converged_sources)]
        if lr is None or track.observe is None or len(followed) != 3 or \
                any(b is not beh for b in followed):
            return "its evolving situations are not followed by one learning behaviour alone"
    return np.array(ev.ids, dtype=np.int64), int(ev.n_situations), ev


def prepare(res: Any, spec: Any, parts: Any, track: Any = None) -> Fused | str:
    """The compiled form of a trial whose loop has nothing else to do (the module docstring),
    or why it runs the Python loop. ``track`` is the trial's
    :class:`~sitframe.runs.tracker.SituationTracker` (evolving situations), or ``None``."""
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
    sits = _evolving(itp, parts, lr, track)
    if isinstance(sits, str):
        return sits
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
               np.array(rw.get("sines", [0.0]), dtype=np.float64), *sits, track)
    why = _agrees(fz, parts)
    return why if why else fz


def _reference(fz: Fused, parts: Any, reading: np.ndarray, centers: np.ndarray,
               ids: np.ndarray) -> np.ndarray:
    """The interpreter's (c,) memberships of ``reading`` (an evolving one's over the feature
    ``centers`` with ``ids``, computed as its ``memberships`` does but without changing it)."""
    ev = fz.situations
    if ev is None:
        return parts.interp.memberships(reading)
    u = np.zeros(fz.c)
    u[ids] = ev._u.from_d2(row_sq_norms(centers - ev.features(reading)))
    return u


def _agrees(fz: Fused, parts: Any) -> str:
    """'' when the kernel's memberships, controller outputs, soft-max draws and value of the
    next situation (and, for evolving situations, the on-line update's memberships to the
    power m) equal the Python components' on probes (fixed, not the trial's draws); else what
    differed. (Evolving situations with no prototype yet are probed with prototypes at the
    first probe readings.)"""
    probe = np.random.default_rng(20261207)
    d = fz.rays.size // int(fz.ip[0])
    readings = np.vstack([probe.uniform(0.0, fz.fp[0], (12, d)), np.full((1, d), fz.fp[0]),
                          probe.uniform(0.0, 0.3, (3, d))])
    lr = fz.learner
    prm = lr.params if lr is not None else None
    tau = prm.temperature if prm is not None else 1.0
    relative = prm is None or prm.temperature_mode == "relative"
    m = 2.0 if fz.situations is None else float(fz.situations.m)
    centers, ids = fz.centers, fz.ids
    if not centers.shape[0]:
        ev = fz.situations
        centers = np.array([ev.features(r) for r in readings[:2]])
        ids = np.arange(2, dtype=np.int64)
    for name, fcs in (("heading", fz.heading), ("speed", fz.speed)):
        if fcs is None:
            continue
        singles, onehot = fz.output(name)
        q = probe.normal(250.0, 30.0, (fz.c, singles.size))
        got, outs, mine, v, um = fz.kernels.probe(
            readings, centers, ids, fz.c, fz.fp, fz.ip, fz.loops, onehot, singles, q,
            float(tau), relative, np.random.default_rng(7), m, _POWER.get(m, 0))
        for r, u, o in zip(readings, got, outs, strict=True):
            ref = _reference(fz, parts, r, centers, ids)
            if not np.array_equal(ref, u):
                return "the compiled memberships differ from the interpreter's"
            if fcs.output(ref) != o:
                return f"the compiled {name} output differs from the behaviour's"
        if not np.array_equal(um, got[0][ids] ** m):
            return "the compiled memberships to the power m differ from numpy's"
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
    is told after every :data:`EVERY` iterations (the caller tells the rest). An evolving
    interpreter answers the iterations the kernel hands it (:class:`_Situations`), and the
    trial's tracker delivers its events between two calls, the learner's state handed back
    and forth around them (:class:`_LearnerState`).
    """
    L, fk = spec.iterations, fz.kernels
    learned = fz.speed if fz.learned == "speed" else fz.heading
    a = np.asarray(learned.singletons).size
    d = rec.reading.shape[1]
    sits = _Situations(fz, d)
    learn = _LearnerState(fz, learned, sits)
    state = np.array([*learn.scalars(), 1, 0, 0], dtype=np.int64)
    carry = np.zeros(11)
    carry[:3] = env.start
    reading, u, r1, u1 = np.empty(d), np.empty(fz.c), np.empty(d), np.empty(fz.c)
    world, none2, rp = env.world, np.full(2, np.nan), fz.rp
    rewards = rec.rewards[:, 0] if rec.rewards.shape[1] else np.empty(L)  # (none: unwritten)
    snaps = (np.empty(EVERY, np.int64), np.empty((EVERY, fz.c), np.int64),
             np.empty((EVERY, fz.c), np.int64), np.empty((EVERY, fz.c, a)))  # (a call's)
    t = 0
    while t < L:
        t1 = min(L, (t // EVERY + 1) * EVERY)
        if chain is not None:
            t1 = min(t1, chain.first[-1] + chain.episode)
        state[6] = 0
        after, hit, contact, resume = carry[:3], False, none2, False
        seg = world.segment_set.packed
        while (code := fk.run(
                t1, resume, after, hit, contact, seg, fz.times, rp, fz.rw, fz.side, fz.sines,
                fz.rays, *sits.arrays(), sits.ev, sits.evf, *sits.arrays_after(),
                *learn.tables, learn.q, learn.updates, learn.visits, learn.rule_base,
                learn.greedy, learn.rules_it, learn.td, learn.removed, fz.fp, fz.ip, state,
                carry, reading, u, r1, u1, env.rng, *fz.call_args(), rec.pose, rec.reading,
                rec.memberships, rec.command, rec.nearest, rec.collision, rec.contact, rewards,
                *snaps)) != fk.DONE:
            resume = code == fk.NEED_STEP
            if resume:
                out = step_robot(world, carry[:3].copy(),
                                 Command(float(carry[3]), float(carry[4])), res.robot, env.rng)
                after, hit, contact = np.array(out.pose), bool(out.collided), \
                    np.array(out.contact_xy)
            elif code == fk.NEED_FIRST:
                u[:] = sits.memberships(reading)
                state[4] = 0
            elif code == fk.NEED_NEXT:
                u1[:] = sits.memberships(r1)
            elif code == fk.NEED_SYNC:  # (the tracker delivers after iteration state[5] - 1)
                learn = learn.deliver(state, int(state[5]) - 1)
            else:  # (NEED_CHECK: TD errors the tracker refuses, naming the learner)
                learn.write_back(state)
                fz.track.step(int(state[5]) - 1)
                raise AssertionError("fused: the tracker took TD errors the kernel refused")
        learn.snapshots(snaps, int(state[6]))
        t = t1
        if t % RELEASE == 0:
            scratch.release_all()
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
    sits.out()
    learn.write_back(state)
    return L


class _Situations:
    """The situations as the kernel takes them: fixed centres, or an evolving interpreter's
    own arrays (changed in place by both) and its scalars, handed to it around each of its
    own ``memberships`` calls and taken back after."""

    def __init__(self, fz: Fused, d: int) -> None:
        fk, self.interp, self.track = fz.kernels, fz.situations, fz.track
        self.at = {name: i for i, name in enumerate(fk.EV)}
        self.ev, self.evf = np.zeros(len(fk.EV), np.int64), np.zeros(len(fk.EVF))
        self.xp, self.xl = np.zeros(d), np.zeros(d)
        c, ev, itp = fz.c, self.ev, self.interp
        self.fixed = (np.array(fz.centers, dtype=np.float64), np.zeros(c), fz.ids)
        self.fixed_after = (np.zeros(d), self.xp, self.xl, np.zeros(c, np.int64), np.zeros(c),
                            np.zeros(c), np.zeros((c, d)))
        if itp is None:
            ev[self.at["check_every"]] = 1
            return
        tr = self.track
        for key, v in (("evolving", 1), ("create_after", itp.create_after),
                       ("check_every", itp.check_every), ("grow_until", itp.grow_until),
                       ("capacity", itp.capacity),
                       ("prune_after", itp.prune_after), ("adapt", itp.adapt),
                       ("observe", tr is not None), ("m_power", _POWER.get(itp.m, 0))):
            ev[self.at[key]] = v
        self.evf[:] = itp.create_d2, itp.m
        self.back()

    def arrays(self) -> tuple[np.ndarray, ...]:
        """``Fa, Na, ids`` as the kernel takes them (the interpreter's own, now)."""
        itp = self.interp
        return self.fixed if itp is None else (itp.Fa, itp.Na, itp.ids)

    def arrays_after(self) -> tuple[np.ndarray, ...]:
        """``streak_sum, xp, xl, last_win, err_sum, err_n, err_x`` as the kernel takes them."""
        itp = self.interp
        return self.fixed_after if itp is None else (
            itp.streak_sum, self.xp, self.xl, itp.last_win, itp.err_sum, itp.err_n, itp.err_x)

    def back(self) -> None:
        """Take the interpreter's scalars (and the tracker's) into ``ev``."""
        itp, ev, at, tr = self.interp, self.ev, self.at, self.track
        if itp is None:
            return
        ev[at["t"]], ev[at["streak"]], ev[at["frozen"]] = itp.t, itp.streak, itp.frozen
        ev[at["next_id"]], ev[at["refused"]] = itp.next_id, itp.refused
        for key, x, buf in (("has_prev", itp.x_prev, self.xp), ("has_last", itp.x_last, self.xl)):
            ev[at[key]] = x is not None
            if x is not None:
                buf[:] = x
        ev[at["tell"]] = tr is not None and tr.tell is not None
        ev[at["deliver"]] = bool(itp.pending)

    def out(self) -> None:
        """Hand ``ev``'s scalars to the interpreter."""
        itp, ev, at = self.interp, self.ev, self.at
        if itp is None:
            return
        itp.t, itp.streak = int(ev[at["t"]]), int(ev[at["streak"]])
        itp.refused = int(ev[at["refused"]])
        itp.x_prev = self.xp.copy() if ev[at["has_prev"]] else None
        itp.x_last = self.xl.copy() if ev[at["has_last"]] else None

    def memberships(self, reading: np.ndarray) -> np.ndarray:
        """The interpreter's own memberships of ``reading`` (it may create, merge, prune or
        split: its events then wait for the iteration's end)."""
        self.out()
        u = self.interp.memberships(reading.copy())
        self.back()
        return u


class _LearnerState:
    """A learner's arrays as the kernel takes them (or stand-ins when the rules are fixed),
    the controllers' rule tables, and their return to the :class:`~sitframe.FuzzyQLearner`
    (after the trial, and around the delivery of evolving situations' events)."""

    def __init__(self, fz: Fused, fcs: Any, sits: _Situations) -> None:
        lr, c, a = fz.learner, fz.c, np.asarray(fcs.singletons).size
        self.fz, self.fcs, self.lr, self.sits = fz, fcs, lr, sits
        self.rule_base = np.asarray(fcs.rule_actions).astype(np.int64)
        self.onehot = np.zeros((c, a))
        self.onehot[np.arange(c), self.rule_base] = 1.0
        (heads, onehot), (speeds, onehot_s) = fz.output("heading"), fz.output("speed")
        if fz.learned == "speed":  # (the learner changes its output's table in place)
            onehot_s = self.onehot
        else:
            onehot = self.onehot
        self.tables = (heads, onehot, speeds, onehot_s)
        self.visits = np.zeros((c, a), dtype=np.int64)
        if lr is None:
            self.q, self.updates, self.greedy = np.zeros((c, a)), np.zeros(c, np.int64), \
                self.rule_base.copy()
            self.rules_it = np.zeros((1, c), dtype=np.int8)
            self.td, self.removed = np.zeros(c), np.zeros(c, dtype=bool)
            self.converged, self.stable, self.since, self.changes = -1, 0, 0, 0
            return
        self.q, self.updates, self.rules_it = lr.q, lr.updates, lr.rules_per_iteration
        self.td, self.removed = lr.td_abs, lr.removed
        self.greedy = np.asarray(lr.greedy, dtype=np.int64).copy()
        for (i, k), n in lr._visits.items():
            self.visits[i, k] = n
        self.converged = -1 if lr.converged_at is None else lr.converged_at
        self.stable, self.since, self.changes = lr.stable_changes, lr.since_change, lr.n_changes
        sits.ev[sits.at["track_td"]], sits.ev[sits.at["evolved"]] = lr.track_td, lr._evolving

    def scalars(self) -> tuple[int, int, int, int]:
        """``state[:4]``: converged at (-1: not), stable changes, since the last, changes."""
        return self.converged, self.stable, self.since, self.changes

    def snapshots(self, snaps: tuple[np.ndarray, ...], k: int) -> None:
        """Append the ``k`` rule-base changes of a call to the learner's snapshots (copied
        into their :class:`~sitframe.learning.fuzzy_q.RowStack`: the buffers are the next
        call's)."""
        if self.lr is None or not k:
            return
        it, rules, greedy, q = snaps
        self.lr._snap_iter.extend(it[:k].tolist())
        self.lr._snap_rules.extend(rules[:k])
        self.lr._snap_greedy.extend(greedy[:k])
        self.lr._snap_q.extend(q[:k])

    def write_back(self, state: np.ndarray) -> None:
        """The learner's scalars, rule bases and learning-rate counts, now."""
        lr = self.lr
        if lr is None:
            return
        lr.converged_at = None if state[0] < 0 else int(state[0])
        lr.stable_changes, lr.since_change, lr.n_changes = (int(v) for v in state[1:4])
        lr.rule_base, lr.greedy = self.rule_base.copy(), self.greedy.copy()
        lr._vmax = None
        lr._visits = {(int(i), int(k)): int(n) for (i, k), n in np.ndenumerate(self.visits)
                      if n}
        lr.track_td = bool(self.sits.ev[self.sits.at["track_td"]])
        self.fcs.set_rules(lr.rule_base)

    def deliver(self, state: np.ndarray, iteration: int) -> _LearnerState:
        """Hand the learner and the interpreter their state, let the tracker deliver after
        ``iteration`` (``SituationTracker.deliver``), and take both back: the learner's as a
        new state (``state[:4]`` too), its rows and rule tables as the events left them."""
        sits = self.sits
        self.write_back(state)
        sits.out()
        self.fz.track.deliver(iteration)
        sits.back()
        new = _LearnerState(self.fz, self.fcs, sits)
        state[:4] = new.scalars()
        return new
