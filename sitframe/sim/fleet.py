"""N robots in one world stepped together: :func:`step_robots`.

Row ``i`` of :func:`step_robots` is exactly ``step_robot(world, poses[i],
commands[i], params, rngs[i])``, bit for bit (``tests/test_kernels.py``). The
work that costs is done for all N robots at once by compiled kernels
(:mod:`sitframe.sim.kernels_numba`), phase by phase of ``step_robot``:

1. which walls each robot's swept disc can reach, and the arguments of its
   substeps' sines and cosines (:func:`~sitframe.sim.kernels_numba.sweep_begin`);
2. the substep poses of the robots near a wall and their first contact
   (:func:`~sitframe.sim.kernels_numba.sweep_end`);
3. the two rounds that refine each contact
   (:func:`~sitframe.sim.kernels_numba.refine`);
4. the contact points and the back-offs of the robots that touched
   (:func:`~sitframe.sim.kernels_numba.contact_points`,
   :func:`~sitframe.sim.kernels_numba.backoffs`).

Between the phases numpy takes the sines and cosines of all robots in one call
each (the kernels leave trigonometry to numpy, see :mod:`sitframe.sim.kernels_numba`).
What is left per robot is Python, as in ``step_robot``: the closed-form pose of
a robot in open space and the cosine and sine of each final heading (with
:mod:`math`), the :class:`~sitframe.sim.robot.StepOutcome`, and for a robot that
touched a wall (about one step in eight under random actions) the contact
normal and the turn away (``step_robot``'s own ``_normal`` and ``_turn_away``,
which may draw from that robot's ``rng``).

Without the compiled kernels (numba missing, ``SITFRAME_NUMBA=0``, or a
process's first :data:`sitframe.sim.kernels.WARMUP_CALLS` calls) each robot goes
through :func:`~sitframe.sim.robot.step_robot`: the same numbers either way.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from types import ModuleType
from typing import Any

import numpy as np

from sitframe.sim.geometry import SegmentSet
from sitframe.sim.kernels import kernels
from sitframe.sim.robot import (
    _BACKOFF_SAMPLES,
    _NAN2,
    _REFINE,
    Command,
    RobotParams,
    StepOutcome,
    _normal,
    _plan,
    _pose_at,
    _times,
    _turn_away,
    _wrap,
    step_robot,
)
from sitframe.sim.world import World

__all__ = ["step_robots"]

_ORIGIN = np.zeros(3)
#: ``v, omega, t_turn`` of each command object seen (they do not depend on the pose; the
#: vector env reuses one object per discrete action), per robot parameters object; an entry
#: holds its object, so the id it is filed under cannot be reused while it is there. At most
#: :data:`_MAX_MOTIONS` commands each (continuous actions are all new).
_MOTIONS: dict[int, tuple[RobotParams, dict[int, tuple[Any, ...]], np.ndarray]] = {}
_MAX_MOTIONS = 4096


def step_robots(world: World, poses: Sequence[np.ndarray], commands: Sequence[Command],
                params: RobotParams, rngs: Sequence[np.random.Generator]) -> list[StepOutcome]:
    """Execute one command per robot, as :func:`sitframe.sim.robot.step_robot` executes each.

    Parameters
    ----------
    world
        The world all robots are in (robots do not collide with each other).
    poses
        N start poses, each (3,) x [m], y [m], theta [rad].
    commands
        N commands.
    params
        Robot parameters, shared.
    rngs
        N generators; robot ``i``'s is used only to break the tie of a dead-ahead contact.

    Returns
    -------
    list of StepOutcome
        N outcomes; outcome ``i`` equals ``step_robot(world, poses[i], commands[i], params,
        rngs[i])``.
    """
    n = len(poses)
    if not (len(commands) == n == len(rngs)):
        raise ValueError(f"step_robots: expected as many commands and rngs as poses ({n}), "
                         f"got {len(commands)} and {len(rngs)}")
    kern = kernels()
    segs = world.segment_set
    if kern is None or segs.n == 0 or n == 0:
        return [step_robot(world, p, c, params, g)
                for p, c, g in zip(poses, commands, rngs, strict=True)]
    plans, margin = _plans(poses, commands, params)
    T = params.control_period_s
    times = _times(T, params.substep_s)
    # step 1 and 2 for all: the segments within reach, the substeps, the first contact
    idx = np.empty((n, segs.n), dtype=np.intp)
    ints = np.empty((4, n), dtype=np.intp)
    count, slot, first, hits = ints
    args = np.empty((2, n, times.size))
    b = kern.sweep_begin(plans, times, T, margin, segs.packed, idx, count, slot, args[0],
                         args[1])
    if b < 0:
        bad = next(p for p in poses if not np.isfinite(np.asarray(p, dtype=float)).all())
        raise ValueError(f"pose must be 3 finite numbers (x, y, theta_rad), got {bad!r}")
    rows = plans[:, :6].tolist()
    for i, c in enumerate(count.tolist()):  # math's cos and sin, as step_robot's _poses_at
        if c:
            th_end = rows[i][2] + rows[i][4] * rows[i][5]
            plans[i, 6], plans[i, 7] = math.cos(th_end), math.sin(th_end)
    xs = np.empty((b, 3, times.size))
    state, active = np.empty((n, 5)), np.empty(n, dtype=np.bool_)
    ref = np.empty((3, n, _REFINE + 1))  # refinement samples and their sine/cosine arguments
    r2 = params.radius * params.radius
    sa, aa = args[0, :b], args[1, :b]
    h = kern.sweep_end(times, plans, slot, sa, np.sin(sa), np.cos(aa), np.sin(aa), segs.packed,
                       idx, count, r2, xs, first, hits, state, active, *ref)
    outs = _free_outcomes(poses, rows, *ints.tolist()[:3], xs, T)
    if h:  # steps 3 and 4 for those that touched a wall
        _refine(kern, plans, hits, h, ref, segs, idx, count, r2, state, active)
        _recover(kern, outs, poses, rows, hits, h, state, first, segs, idx, count, params, rngs)
    return outs  # type: ignore[return-value]


def _array(pose: np.ndarray) -> np.ndarray:
    """``step_robot``'s ``pose_before``: the pose itself when it is an array."""
    return pose if isinstance(pose, np.ndarray) else np.asarray(pose, dtype=float)


def _plans(poses: Sequence[np.ndarray], commands: Sequence[Command],
           params: RobotParams) -> tuple[np.ndarray, np.ndarray]:
    """(N, 8) rows ``x0, y0, th0, v, omega, t_turn`` of ``step_robot``'s ``_plan`` (and room
    for the cosine and sine of the final heading), and the (3,) margins of the swept disc's
    reach beyond ``v * period``: the radius, the back-off and a hair."""
    plans = np.empty((len(poses), 8))
    plans[:, :3] = np.array(poses)
    seen = _MOTIONS.get(id(params))
    if seen is None or seen[0] is not params or len(seen[1]) > _MAX_MOTIONS:
        if len(_MOTIONS) > 64:
            _MOTIONS.clear()
        seen = _MOTIONS[id(params)] = (params, {}, np.array([params.radius,
                                                              params.recovery_backoff_m, 1e-9]))
    motions = []
    for c in commands:  # (keyed by the command's id, which the entry keeps alive)
        m = seen[1].get(id(c))
        if m is None or m[0] is not c:
            m = seen[1][id(c)] = (c, _plan(_ORIGIN, c, params)[3:])
        motions.append(m[1])
    plans[:, 3:6] = np.array(motions)
    return plans, seen[2]


def _refine(kern: ModuleType, plans: np.ndarray, hits: np.ndarray, h: int, ref: np.ndarray,
            segs: SegmentSet, idx: np.ndarray, count: np.ndarray, r2: float, state: np.ndarray,
            active: np.ndarray) -> None:
    """``step_robot``'s two refinement rounds for the ``h`` robots ``hits`` that touched."""
    fposes = np.empty((h, 3, _REFINE + 1))
    ts, sa, aa = ref[0], ref[1], ref[2]
    for more in (True, False):
        s0, c1, s1 = np.sin(sa[:h]), np.cos(aa[:h]), np.sin(aa[:h])
        kern.refine(plans, hits, h, ts, sa, aa, s0, c1, s1, segs.packed, idx, count, r2, state,
                    active, fposes, more)


def _recover(kern: ModuleType, outs: list[StepOutcome | None], poses: Sequence[np.ndarray],
             rows: list[list[float]], hits: np.ndarray, h: int, state: np.ndarray,
             first: np.ndarray, segs: SegmentSet, idx: np.ndarray, count: np.ndarray,
             params: RobotParams, rngs: Sequence[np.random.Generator]) -> None:
    """``step_robot``'s contact point and recovery for the ``h`` robots ``hits`` that touched,
    into ``outs``: the points and the back-offs in one compiled call each, the contact normal
    and the turn (:mod:`math`, and the robot's ``rng`` for a dead-ahead tie) per robot."""
    contact = np.empty((h, 2))
    kern.contact_points(hits, h, state, segs.packed, idx, count, contact)
    st = state[:h, :4].tolist()  # t_c, cx, cy, cth
    backed = [(0.0, s[1], s[2]) for s in st]
    if params.recovery != "none" and params.recovery_backoff_m > 0.0:
        normals = np.array([_normal(s[1], s[2], s[3], c)
                            for s, c in zip(st, contact.tolist(), strict=True)])
        out = np.empty((h, 3))
        kern.backoffs(hits, h, state, normals, params.recovery_backoff_m, segs.packed, idx,
                      count, params.radius * params.radius, first, np.empty(_BACKOFF_SAMPLES),
                      out)
        backed = out.tolist()
    for q, i in enumerate(hits[:h].tolist()):
        t_c, cx, cy, cth = st[q]
        outs[i] = _turn_away(_array(poses[i]), rows[i], t_c, (cx, cy, cth), contact[q],
                             backed[q], params, rngs[i])


def _free_outcomes(poses: Sequence[np.ndarray], rows: list[list[float]], count: list[int],
                   slot: list[int], first: list[int], xs: np.ndarray,
                   T: float) -> list[StepOutcome | None]:
    """The outcomes of the robots that touched nothing (None for the others), as
    ``step_robot`` writes them: its closed form in open space, the last substep else."""
    last = xs[:, :, -1].tolist()  # the last substep's pose of each robot near a wall
    free = [i for i in range(len(rows)) if first[i] < 0]
    ends = [_pose_at(T, *rows[i]) if count[i] == 0 else last[slot[i]] for i in free]
    finals = np.array([(x, y, _wrap(th)) for x, y, th in ends])  # (one array; a row each)
    outs: list[StepOutcome | None] = [None] * len(rows)
    for q, i in enumerate(free):
        final, row = finals[q], rows[i]
        pose = poses[i]
        outs[i] = StepOutcome(pose if pose.__class__ is np.ndarray else _array(pose), final,
                              False, _NAN2, final, row[3] * T, math.degrees(ends[q][2] - row[2]))
    return outs
