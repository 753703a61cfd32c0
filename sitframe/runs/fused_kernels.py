"""The compiled learning trial: one call runs many control iterations (:mod:`sitframe.runs.fused`).

:func:`run` is the control loop of :mod:`sitframe.runs.loop` for one configuration of
built-in components -- a range-finder ring without noise, fixed fuzzy c-means situations, one
``fuzzy-q`` behaviour (a heading output and optionally a speed output, at most one of them
learned), the ``single`` arbiter and a built-in reward (:data:`REWARDS`) -- with every
operation in the order the Python components perform it, so the log is the same to the
bit. Sines and cosines are the C library's (used only where they are numpy's,
:func:`sitframe.sim.kernels.fused`); logarithms, powers, exponentials and dot products are
numpy's own loops and OpenBLAS's ``ddot``, reached through pointers
(:mod:`sitframe.sim.numpy_loops`); sums follow numpy's pairwise order.

A step that touches a wall is left to Python: :func:`run` returns :data:`NEED_STEP` with the
command in ``carry``, the caller runs ``robot.step_robot`` (contact, refinement, back-off and
turn, with the trial's Generator) and calls again with its outcome. Touching is rare (a few
per hundred iterations while learning), and the contact's arithmetic then stays in one place.

Arrays (``c`` situations, ``A`` headings, ``d`` readings, ``L`` iterations):

``fp`` (float64)
    see :data:`FP`; ``ip`` (int64): see :data:`IP`; ``rp``: the robot's parameters
    (:data:`sitframe.sim.kernels_numba.ROBOT`).
``state`` (int64)
    ``converged_at`` (-1: not), stable changes, iterations since the last change, changes,
    whether the next iteration reads first (a trial's or an episode's start), the next
    iteration, snapshots written.
``carry``
    (3 + 2 + 6,) the pose, the command of a step left to Python and, while Python computes
    the next reading's memberships, the step's outcome (pose, collided, contact);
    ``reading`` (d,), ``u`` (c,) the current reading and memberships, ``r1``, ``u1`` the next.
``ev`` (int64), ``evf`` (float64)
    the situations' state and settings, see :data:`EV` and :data:`EVF`: fixed ``fcm``
    situations (``ev[0] = 0``: ``Fa`` the centres, ``ids`` ``0 .. c - 1``) or the
    ``evolving`` interpreter's (:func:`situate`: ``Fa``, ``Na`` its alive prototypes and
    evidence, ``ids`` their ids, and its streak, error and last-win arrays, all its own,
    changed in place).

Evolving situations: an iteration whose memberships would create a situation, or run the
every-``check_every`` merge, prune and split, or meet no prototype (or more than
:data:`~sitframe.sim.kernels_numba.PAIRWISE_MAX`), is handed to Python before anything
changes (:data:`NEED_FIRST`, :data:`NEED_NEXT`: the interpreter's own ``memberships``); an
iteration after which the interpreter has events to deliver, or every learner has just
converged and the interpreter is to be told, returns :data:`NEED_SYNC` once it is done
(Python delivers them: :meth:`sitframe.runs.tracker.SituationTracker.deliver`).

Why one module of this size: it is the trial kernel's unit of compiling and caching. Its
helpers are inlined into :func:`run`, numba caches it as one file, and a first run after an
install compiles it in one background process
(:func:`sitframe.sim.numba_cache.compile_elsewhere`); split, the halves would be compiled and
cached, and waited for, apart.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from sitframe.sim import numpy_loops
from sitframe.sim.kernels_numba import (
    _JIT,
    FREE,
    PAIRWISE_MAX,
    TIE,
    TOUCH,
    _pairwise_sum,
    accumulate_errors,
    fcm_online_update,
    fcm_ratios,
    finish_turn,
    frozen_td,
    label_strengths,
    normalize,
    ranges_at,
    robot_step,
)

#: Small helpers are inlined into their callers when typed (numba compiles no function of
#: their own for them, which saves seconds of the first compile).
_INLINE = {**_JIT, "inline": "always"}

#: Names of the float parameters ``fp``, in order.
FP = ("max_range", "sensor_radius", "offset", "p", "floor", "alpha", "gamma", "activation",
      "temperature", "temperature_decay", "temperature_min", "alpha_visits", "default_speed")
#: The rewards the kernel computes (``ip[14]``) and their parameters ``rw``, in order.
REWARDS = {"obstacle-avoidance": ("collision", "base", "heading_cost"),
           "wall-following": ("near", "far", "collision", "too_close", "lost", "inside",
                              "approach", "explore", "heading_cost", "robot_radius",
                              "max_range", "approach_min"),
           "speed": ("collision", "near", "base", "per_mm_s", "near_time_s")}
#: Names of the integer parameters ``ip``, in order.
IP = ("rays_per_beam", "transform", "power", "has_learner", "learning", "b", "p_changes",
      "min_updates", "thesis", "terminal", "tie_centre", "relative", "decay", "contact",
      "reward", "has_speed", "learns_speed", "clip")
#: The situations' integer state ``ev``, in order: evolving (0: fixed ``fcm`` centres), frozen,
#: the interpreter's ``t``, its streak of poorly covered readings, ``create_after``,
#: ``check_every``, ``grow_until``, ``prune_after``, ``adapt``, whether it has a previous and
#: a last reading, whether the trial feeds it TD errors, whether it waits to be told the rules
#: converged, whether events wait to be delivered, whether the learner tracks TD errors, how
#: ``u ** m`` is computed, whether the learner's situations evolved (``min_updates`` over live
#: rows), the iteration to resume at with the next reading's memberships given (0: none), the
#: next id, the capacity and the situations refused for want of an id.
EV = ("evolving", "frozen", "t", "streak", "create_after", "check_every", "grow_until",
      "prune_after", "adapt", "has_prev", "has_last", "observe", "tell", "deliver", "track_td",
      "m_power", "evolved", "given", "next_id", "capacity", "refused")
#: The situations' float settings ``evf``: the squared create distance, and ``m``.
EVF = ("create_d2", "m")
(_ON, _FROZEN, _T, _STREAK, _AFTER, _CHECK, _GROW, _PRUNE, _ADAPT, _PREV, _LAST, _OBSERVE,
 _TELL, _DELIVER, _TD, _MPOW, _EVOLVED, _GIVEN, _NEXT, _CAP, _REFUSED) = range(len(EV))
#: :func:`run`'s answers: the chunk is done; a step touches a wall (Python steps it); Python
#: computes the memberships of ``reading`` (a trial's or episode's first) or of ``r1`` (the
#: next); events or the rules' convergence wait for Python after the iteration.
#: (And after an iteration whose TD errors are not finite and >= 0, which the tracker refuses.)
DONE, NEED_STEP, NEED_FIRST, NEED_NEXT, NEED_SYNC, NEED_CHECK = 0, 1, 2, 3, 4, 5
#: How ``w ** p`` is computed, as numpy's in-place power chooses for a scalar exponent.
POW_LOOP, POW_ONE, POW_RECIPROCAL, POW_ZERO, POW_SQRT, POW_SQUARE = range(6)


@njit(**_INLINE)
def _loop1(f, ctx, aux, x, out, n, ptrs, dims, strides):  # pragma: no cover - compiled
    """numpy's unary loop ``f`` over ``x[:n]`` into ``out[:n]``."""
    ptrs[0], ptrs[1] = x.ctypes.data, out.ctypes.data
    dims[0] = n
    strides[0], strides[1] = 8, 8
    f(ctx, ptrs.ctypes.data, dims.ctypes.data, strides.ctypes.data, aux)


@njit(**_INLINE)
def _power(w, p, mode, f, ctx, aux, ptrs, dims, strides, scalar):  # pragma: no cover
    """``w **= p`` in place, as numpy computes it for a Python float ``p``."""
    if mode == POW_LOOP:
        scalar[0] = p
        ptrs[0], ptrs[1], ptrs[2] = w.ctypes.data, scalar.ctypes.data, w.ctypes.data
        dims[0] = w.size
        strides[0], strides[1], strides[2] = 8, 0, 8
        f(ctx, ptrs.ctypes.data, dims.ctypes.data, strides.ctypes.data, aux)
        return
    for i in range(w.size):
        x = w[i]
        if mode == POW_RECIPROCAL:
            w[i] = 1.0 / x
        elif mode == POW_ZERO:
            w[i] = 1.0
        elif mode == POW_SQRT:
            w[i] = math.sqrt(x)
        elif mode == POW_SQUARE:
            w[i] = x * x


@njit(**_INLINE)
def _copy(src, dst):  # pragma: no cover - compiled
    """``dst[:] = src`` (1-D; a slice assignment costs numba seconds of compiling)."""
    for i in range(src.size):
        dst[i] = src[i]


@njit(**_INLINE)
def row_norms(X, out):  # pragma: no cover - compiled
    """``np.einsum("ij,ij->i", X, X)`` in einsum's own order (x86-64 baseline: two lanes,
    blocks of eight summed from the last pair to the first, the tail in pairs)."""
    n, d = X.shape
    for i in range(n):
        lane0 = 0.0
        lane1 = 0.0
        k = 0
        while d - k >= 8:
            for j in (6, 4, 2, 0):
                lane0 = X[i, k + j] * X[i, k + j] + lane0
                lane1 = X[i, k + j + 1] * X[i, k + j + 1] + lane1
            k += 8
        while k < d:
            lane0 = X[i, k] * X[i, k] + lane0
            second = X[i, k + 1] if k + 1 < d else 0.0
            lane1 = second * second + lane1
            k += 2
        out[i] = 0.0 + (lane0 + lane1)


@njit(**_INLINE)
def _features(reading, fp, ip, feat, lg, ptrs, dims, strides):  # pragma: no cover - compiled
    """``FCMInterpreter.features(reading)`` into ``feat``."""
    transform, offset = ip[1], fp[2]
    for j in range(reading.size):
        if transform == 0:
            feat[j] = reading[j]
        elif transform == 1:
            feat[j] = reading[j] + offset
        else:
            feat[j] = 1.0 / (reading[j] + offset)
    if transform == 1:
        _loop1(lg[0], lg[1], lg[2], feat, feat, feat.size, ptrs, dims, strides)


@njit(**_INLINE)
def _distances(fc, feat, diff, d2):  # pragma: no cover - compiled
    """``diff = fc - feat`` and its rows' squared norms ``d2`` (``row_sq_norms``)."""
    for i in range(fc.shape[0]):
        for j in range(fc.shape[1]):
            diff[i, j] = fc[i, j] - feat[j]
    row_norms(diff, d2)


@njit(**_INLINE)
def _from_d2(d2, fp, ip, u, pw, ptrs, dims, strides, scalar):  # pragma: no cover - compiled
    """``MembershipFunction.from_d2(d2)`` into ``u``."""
    if fcm_ratios(d2, fp[4], u) <= 0.0:  # on a centre: shared equally among those it is on
        on = 0
        for i in range(d2.size):
            on += d2[i] <= 0.0
        for i in range(d2.size):
            u[i] = (1.0 if d2[i] <= 0.0 else 0.0) / on
        return
    _power(u, fp[3], ip[2], pw[0], pw[1], pw[2], ptrs, dims, strides, scalar)
    normalize(u)


@njit(**_INLINE)
def _covered(t, d2, feat, ev, evf, streak_sum):  # pragma: no cover - compiled
    """``EvolvingInterpreter._cover`` at its ``t``-th reading (features ``feat``, squared
    distances ``d2`` to the alive prototypes): the streak of poorly covered readings counted,
    or reset; ``False`` (nothing changed) when the checks are due or a situation is created."""
    if t % ev[_CHECK] == 0:
        return False
    if not (ev[_GROW] == 0 or t <= ev[_GROW]):  # (no longer growing)
        return True
    dmin = d2[0]
    for i in range(1, d2.size):
        v = d2[i]
        if (v < dmin or v != v) and dmin == dmin:
            dmin = v
    if not (ev[_STREAK] or dmin > evf[0]):  # (the interpreter's test before _cover)
        return True
    if not dmin <= evf[0]:  # (poorly covered, NaN too)
        if ev[_STREAK] + 1 < ev[_AFTER]:
            ev[_STREAK] += 1
            for j in range(streak_sum.size):
                streak_sum[j] += feat[j]
            return True
        if ev[_NEXT] < ev[_CAP]:
            return False  # (a situation is created there)
        ev[_REFUSED] += 1  # (refused: every id is used)
    ev[_STREAK] = 0
    for j in range(streak_sum.size):
        streak_sum[j] = 0.0
    return True


@njit(**_INLINE)
def _follow(t, Fa, Na, ids, diff, feat, ua, um, xp, xl, last_win, ev, evf, pw, ptrs, dims,
            strides, scalar):  # pragma: no cover - compiled
    """The end of ``EvolvingInterpreter.memberships`` (not frozen) at its ``t``-th reading:
    the last two readings, the last win and the on-line update of the alive prototypes."""
    if ev[_LAST]:
        _copy(xl, xp)
        ev[_PREV] = 1
    _copy(feat, xl)
    ev[_LAST] = 1
    n = ua.size
    if ev[_PRUNE]:  # (argmax: the first of the greatest; a NaN wins at once)
        best = 0
        for i in range(1, n):
            if ua[best] != ua[best]:
                break
            if ua[i] > ua[best] or ua[i] != ua[i]:
                best = i
        last_win[ids[best]] = t
    if ev[_ADAPT]:
        _copy(ua, um)
        _power(um, evf[1], ev[_MPOW], pw[0], pw[1], pw[2], ptrs, dims, strides, scalar)
        fcm_online_update(Fa, Na, diff, um)


@njit(**_JIT)
def situate(reading, Fa, Na, ids, fp, ip, ev, evf, feat, diff, d2, ua, um, u, streak_sum, xp,
            xl, last_win, lg, pw, ptrs, dims, strides, scalar):  # pragma: no cover - compiled
    """The situations' memberships of ``reading`` into ``u`` (c,): fixed centres, or
    ``EvolvingInterpreter.memberships`` operation by operation (coverage streak, the
    memberships of the alive prototypes scattered by id, the last readings, the last win and
    the on-line update of the prototypes).

    Returns ``False``, having changed nothing, when the interpreter must answer itself: it has
    no prototype (or more than ``PAIRWISE_MAX``), the reading creates a situation, or its
    merge, prune and split checks are due. (A situation refused for want of an id is counted
    here.)
    """
    n = Fa.shape[0]
    live = ev[_ON] != 0 and ev[_FROZEN] == 0
    if ev[_ON] != 0 and (n == 0 or n > PAIRWISE_MAX):
        return False
    _features(reading, fp, ip, feat, lg, ptrs, dims, strides)
    _distances(Fa, feat, diff, d2)
    t = ev[_T] + 1
    if live and not _covered(t, d2, feat, ev, evf, streak_sum):
        return False
    ev[_T] = t
    _from_d2(d2, fp, ip, ua, pw, ptrs, dims, strides, scalar)
    for i in range(u.size):
        u[i] = 0.0
    for i in range(n):
        u[ids[i]] = ua[i]
    if live:
        _follow(t, Fa, Na, ids, diff, feat, ua, um, xp, xl, last_win, ev, evf, pw, ptrs, dims,
                strides, scalar)
    return True


@njit(**_INLINE)
def _greedy(q, centre, out):  # pragma: no cover - compiled
    """``fuzzy_q.greedy_actions`` into ``out``."""
    c, a = q.shape
    for i in range(c):
        best = 0
        for k in range(1, a):  # (argmax: the first of the greatest; a NaN wins at once)
            if q[i, best] != q[i, best]:
                break
            if q[i, k] > q[i, best] or q[i, k] != q[i, k]:
                best = k
        if centre:  # (the one nearest the middle of the greatest; none if a NaN: the first)
            top, score, pick = q[i, best], -np.inf, 0
            for k in range(a):
                s = -abs(k - (a - 1) / 2.0) if q[i, k] == top else -np.inf
                if s > score:
                    score, pick = s, k
            best = pick
        out[i] = best


@njit(**_JIT)
def _softmax(q, tau, relative, rng, ex, logits, out):  # pragma: no cover - compiled
    """``fuzzy_q.softmax_choice``: one soft-max draw per situation into ``out``."""
    c, a = q.shape
    for i in range(c):
        top, low = q[i, 0], q[i, 0]
        for k in range(1, a):
            v = q[i, k]
            if (v > top or v != v) and top == top:
                top = v
            if (v < low or v != v) and low == low:
                low = v
        den = tau
        if relative:
            spread = top - low
            den = tau * (spread if spread > 0 else 1.0)
        for k in range(a):
            logits[i * a + k] = (q[i, k] - top) / den
    ptrs, dims, strides = np.empty(3, np.intp), np.empty(1, np.intp), np.empty(3, np.intp)
    _loop1(ex[0], ex[1], ex[2], logits, logits, c * a, ptrs, dims, strides)
    for i in range(c):
        total = logits[i * a]
        for k in range(1, a):
            total = total + logits[i * a + k]
            logits[i * a + k] = total
        draw = rng.random() * total
        n = 0
        for k in range(a):
            n += logits[i * a + k] < draw
        out[i] = n if n < a - 1 else a - 1


@njit(**_JIT)
def _change(t, q, updates, removed, evolved, rule_base, greedy, new, state, fp, ip, rng, ex,
            logits, onehot, snap_it, snap_rules, snap_greedy,
            snap_q):  # pragma: no cover - compiled
    """``FuzzyQLearner._change`` at iteration ``t``, its snapshot, and the controller's new
    one-hot rule table. (Explicit loops instead of slice assignments: numba compiles those
    for seconds.)"""
    c, a = q.shape
    state[2] = 0
    _greedy(q, ip[10] != 0, new)
    same = True
    for i in range(new.size):
        same = same and new[i] == greedy[i]
    if same:
        state[1] += 1
    else:
        state[1] = 0
        _copy(new, greedy)
    state[3] += 1
    low = _fewest(updates, removed, evolved)
    if state[1] >= ip[6] and (ip[7] == 0 or low >= ip[7]):
        state[0] = t + 1
        _copy(new, rule_base)
    else:
        tau = fp[8]
        if ip[12]:  # annealed: max(temperature_min, temperature * decay ** changes)
            tau = fp[8] * math.pow(fp[9], float(state[3]))
            tau = tau if tau > fp[10] else fp[10]
        _softmax(q, tau, ip[11] != 0, rng, ex, logits, rule_base)
    k = state[6]
    snap_it[k] = t + 1
    for i in range(c):
        snap_rules[k, i] = rule_base[i]
        snap_greedy[k, i] = new[i]
        for j in range(a):
            snap_q[k, i, j] = q[i, j]
            onehot[i, j] = 1.0 if rule_base[i] == j else 0.0
    state[6] = k + 1


@njit(**_INLINE)
def _fewest(updates, removed, evolved):  # pragma: no cover - compiled
    """``FuzzyQLearner._min_updates``: the fewest updates of a row (with evolving situations,
    of the rows updated at least once and not removed; 0 if none)."""
    gone = False
    for i in range(removed.size):
        gone = gone or removed[i]
    if not gone and not evolved:
        low = updates[0]
        for i in range(1, updates.size):
            low = updates[i] if updates[i] < low else low
        return low
    low = -1
    for i in range(updates.size):
        if not removed[i] and updates[i] > 0 and (low < 0 or updates[i] < low):
            low = updates[i]
    return low if low >= 0 else 0


@njit(**_INLINE)
def _vmax(q, vmax):  # pragma: no cover - compiled
    """``np.maximum.reduce(q, axis=1)`` into ``vmax`` (NaN propagates)."""
    for i in range(q.shape[0]):
        top = q[i, 0]
        for k in range(1, q.shape[1]):
            v = q[i, k]
            if (v > top or v != v) and top == top:
                top = v
        vmax[i] = top


@njit(**_INLINE)
def _v_next(q, u1, collided, ip, dd, vmax):  # pragma: no cover - compiled
    """``V(s')``: ``u1 @ q.max(axis=1)``, or 0 after a collision when it is terminal."""
    if collided and ip[9]:
        return 0.0
    _vmax(q, vmax)
    return dd(q.shape[0], u1.ctypes.data, 1, vmax.ctypes.data, 1)


@njit(**_INLINE)
def _learn(t, u0, u1, reward, collided, q, updates, visits, rule_base, fp, ip, state,
           dd, vmax, td, track):  # pragma: no cover - compiled
    """``FuzzyQLearner.update`` up to the rule-base change (with ``track``, each updated rule's
    absolute TD error in ``td``, 0 elsewhere); whether it is time to change."""
    act, c = fp[7], u0.size
    if track:
        for i in range(c):
            td[i] = 0.0
    any_active = False
    for i in range(c):
        any_active = any_active or act <= 0 or u0[i] >= act
    if any_active:
        v_next = _v_next(q, u1, collided, ip, dd, vmax)
        alpha, gamma, kappa = fp[5], fp[6], fp[11]
        target = reward + gamma * v_next
        for i in range(c):
            if not (act <= 0 or u0[i] >= act):
                continue
            w, a = u0[i], rule_base[i]
            cur = q[i, a]
            if kappa:
                n = visits[i, a]
                visits[i, a] = n + 1
                alpha = fp[5] * kappa / (kappa + n)
            if ip[8]:
                delta = w * reward + gamma * w * v_next - cur
                q[i, a] = cur + alpha * delta
            else:
                delta = target - cur
                q[i, a] = cur + alpha * w * delta
            updates[i] += 1
            if track:
                td[i] = abs(delta)
    state[2] += 1
    return collided or state[2] >= ip[5]


@njit(**_INLINE)
def _learner(t, u, u1, r, hit, q, updates, visits, removed, rule_base, greedy, new, td, fp, ip,
             state, ev, rng, ex, dd, vmax, logits, learned, snap_it, snap_rules, snap_greedy,
             snap_q):  # pragma: no cover - compiled
    """``FuzzyQLearner.update`` of iteration ``t``: learn and change the rule base when it is
    time; once converged, only the TD errors the frozen rules would get (if tracked)."""
    if state[0] < 0:
        if _learn(t, u, u1, r, hit, q, updates, visits, rule_base, fp, ip, state, dd, vmax, td,
                  ev[_TD] != 0):
            _change(t, q, updates, removed, ev[_EVOLVED] != 0, rule_base, greedy, new, state, fp,
                    ip, rng, ex, logits, learned, snap_it, snap_rules, snap_greedy, snap_q)
    elif ev[_TD]:
        frozen_td(u, fp[7] if fp[7] > 0 else -np.inf, ip[8] != 0, r, fp[6],
                  _v_next(q, u1, hit, ip, dd, vmax), q, rule_base, td)


@njit(**_INLINE)
def _record(t, x, y, th, reading, u, heading, speed, hit, hx, hy, pose_out, reading_out, u_out,
            command_out, nearest_out, collision_out, contact_out):  # pragma: no cover
    """Iteration ``t``'s row of the trial's arrays (``Recorder.record``)."""
    pose_out[t, 0], pose_out[t, 1], pose_out[t, 2] = x, y, th
    _copy(reading, reading_out[t])
    _copy(u, u_out[t])
    command_out[t, 0], command_out[t, 1] = heading, speed
    nearest_out[t] = _nearest(reading)
    collision_out[t] = hit
    if hit:
        contact_out[t, 0], contact_out[t, 1] = hx, hy


@njit(**_INLINE)
def _tracked(td, xp, err_sum, err_n, err_x, ev, state):  # pragma: no cover - compiled
    """``SituationTracker.step`` after a learning iteration: the learner's TD errors summed
    at the reading they were learnt on (``observe_errors``). :data:`NEED_CHECK` when they
    are not finite and >= 0 (nothing summed: Python's tracker refuses them), :data:`NEED_SYNC`
    when events or the rules' convergence wait for Python, else :data:`DONE`."""
    ev[_TD] = 1  # (situation_errors() turns the learner's tracking on)
    for i in range(td.size):
        if not (td[i] >= 0.0 and td[i] < np.inf):
            return NEED_CHECK
    if ev[_FROZEN] == 0 and ev[_PREV]:
        accumulate_errors(td, xp, err_sum, err_n, err_x)
    return NEED_SYNC if ev[_DELIVER] != 0 or (ev[_TELL] != 0 and state[0] >= 0) else DONE


@njit(**_JIT)
def run(t1, resume, after, collided_after, contact_after, seg, times, rp, rw, side, sines, rel,
        Fa, Na, ids, ev, evf, streak_sum, xp, xl, last_win, err_sum, err_n, err_x,
        singletons, onehot, speeds, onehot_s, q, updates, visits, rule_base, greedy, rules_it,
        td, removed, fp, ip, state, carry, reading, u, r1, u1, rng, lg, pw, ex, dd, pose_out,
        reading_out, u_out, command_out, nearest_out, collision_out, contact_out, reward_out,
        snap_it, snap_rules, snap_greedy, snap_q):  # pragma: no cover - compiled
    """Run iterations ``state[5]`` up to ``t1`` (exclusive); :data:`DONE`, or
    :data:`NEED_STEP` with the command in ``carry[3:5]`` when a step touches a wall (call
    again with ``resume`` and its outcome: ``after`` (3,) pose, ``collided_after``,
    ``contact_after`` (2,)), or another of the answers of the module docstring. Writes every
    iteration's row of the trial's arrays."""
    c, a = q.shape
    d = reading.size
    feat, diff, d2, ua, um = np.empty(d), np.empty(Fa.shape), np.empty(Fa.shape[0]), \
        np.empty(Fa.shape[0]), np.empty(Fa.shape[0])
    new, vmax = np.empty(c, np.int64), np.empty(c)
    logits, strength, strength_s = np.empty(c * a), np.empty(singletons.size), \
        np.empty(speeds.size)
    learned = onehot_s if ip[16] else onehot  # (the rule table the learner changes)
    ptrs, dims, strides, scalar = np.empty(3, np.intp), np.empty(1, np.intp), \
        np.empty(3, np.intp), np.empty(1)
    touch = np.empty(14)
    t = state[5]
    while t < t1:
        x, y, th = carry[0], carry[1], carry[2]
        if state[4]:  # the trial's or an episode's first reading
            ranges_at(x, y, th, rel, seg, fp[0], fp[1], ip[0], ip[17] != 0, reading)
            if not situate(reading, Fa, Na, ids, fp, ip, ev, evf, feat, diff, d2, ua, um, u,
                           streak_sum, xp, xl, last_win, lg, pw, ptrs, dims, strides, scalar):
                state[5] = t
                return NEED_FIRST  # (Python sets u and clears state[4])
            state[4] = 0
        if ev[_GIVEN] == t + 1:  # the step was done and Python gave the next memberships
            ev[_GIVEN] = 0
            heading, speed = carry[3], carry[4]
            nx, ny, nth, hit, hx, hy = carry[5], carry[6], carry[7], carry[8] != 0.0, \
                carry[9], carry[10]
        else:
            if resume:
                heading, speed = carry[3], carry[4]
                nx, ny, nth = after[0], after[1], after[2]
                hit, hx, hy = collided_after, contact_after[0], contact_after[1]
                resume = False
            else:
                if ip[3]:
                    _copy(rule_base, rules_it[t])
                heading = controller(onehot, u, singletons, dd, strength)
                speed = controller(onehot_s, u, speeds, dd, strength_s) if ip[15] else fp[12]
                code = robot_step(x, y, th, heading, speed, rp, times, seg, ip[13] != 0, touch)
                if code == TOUCH:  # (the contact is stepped in Python: step_robot)
                    carry[3], carry[4] = heading, speed
                    state[5] = t
                    return NEED_STEP
                if code == TIE:  # (dead ahead: the side of the turn away is drawn)
                    finish_turn(touch, rng.random() < 0.5)
                hit = code != FREE
                nx, ny, nth, hx, hy = touch[0], touch[1], touch[2], touch[3], touch[4]
            ranges_at(nx, ny, nth, rel, seg, fp[0], fp[1], ip[0], ip[17] != 0, r1)
            if not situate(r1, Fa, Na, ids, fp, ip, ev, evf, feat, diff, d2, ua, um, u1,
                           streak_sum, xp, xl, last_win, lg, pw, ptrs, dims, strides, scalar):
                carry[3], carry[4], carry[5], carry[6], carry[7] = heading, speed, nx, ny, nth
                carry[8], carry[9], carry[10] = 1.0 if hit else 0.0, hx, hy
                ev[_GIVEN] = t + 1
                state[5] = t
                return NEED_NEXT  # (Python sets u1 and calls again)
        _record(t, x, y, th, reading, u, heading, speed, hit, hx, hy, pose_out, reading_out,
                u_out, command_out, nearest_out, collision_out, contact_out)
        then = DONE
        if ip[4]:
            r = reward(ip[14], rw, side, sines, hit, heading, speed, reading, r1)
            reward_out[t] = r
            if ip[3]:
                _learner(t, u, u1, r, hit, q, updates, visits, removed, rule_base, greedy, new,
                         td, fp, ip, state, ev, rng, ex, dd, vmax, logits, learned, snap_it,
                         snap_rules, snap_greedy, snap_q)
            if ev[_OBSERVE]:
                then = _tracked(td, xp, err_sum, err_n, err_x, ev, state)
        carry[0], carry[1], carry[2] = nx, ny, nth
        _copy(r1, reading)
        _copy(u1, u)
        t += 1
        state[5] = t
        if then != DONE:
            return then
    return DONE


@njit(**_INLINE)
def _nearest(reading):  # pragma: no cover - compiled
    """``np.minimum.reduce(reading)`` (NaN propagates)."""
    best = reading[0]
    for i in range(1, reading.size):
        v = reading[i]
        if (v < best or v != v) and best == best:
            best = v
    return best


@njit(**_INLINE)
def _wall(reading, rw, side, sines):  # pragma: no cover - compiled
    """``WallFollowingReward.wall_distance``: the nearer wall's distance [m] (inf: none)."""
    radius, top, best = rw[9], rw[10] - 1e-9, np.inf
    for j in range(side.size):
        rs = reading[side[j]]
        d = (radius + rs) * sines[j] - radius if rs < top else np.inf
        if d < best:
            best = d
    return best if best >= 0.0 else 0.0  # (numpy.maximum(best, 0.0))


@njit(**_JIT)
def reward(kind, rw, side, sines, hit, heading, speed, r0, r1):  # pragma: no cover
    """The learner's reward of a transition from reading ``r0`` to ``r1`` under ``heading``
    [deg] and ``speed`` [m/s]: ``kind`` 0 the ``obstacle-avoidance`` reward's
    (``ObstacleAvoidanceReward``), 1 the ``wall-following`` one's (``WallFollowingReward``:
    ``side`` its side beams and ``sines`` their sines), 2 the ``speed`` one's
    (``SpeedReward``), with the parameters ``rw`` of :data:`REWARDS`."""
    if kind == 0:
        return rw[0] if hit else (rw[1] - rw[2] * abs(heading)) + 0.0
    if kind == 2:
        if hit:
            return rw[0]
        prev, cur = _nearest(r0), _nearest(r1)
        near = rw[4] * speed
        near = near if near > rw[1] else rw[1]  # (Python's max(near, near_time_s * speed))
        if prev < near and cur < prev:
            return (cur - prev) * 100.0
        return rw[2] + rw[3] * speed * 1000.0
    if hit:
        return rw[2]
    d1 = _wall(r1, rw, side, sines)
    if d1 < rw[0]:
        return rw[3]
    if d1 <= rw[1]:
        r = rw[5]
    elif _wall(r0, rw, side, sines) <= rw[1]:
        return rw[4]
    else:
        n0, n1 = _nearest(r0), _nearest(r1)
        r = rw[6] if n1 < rw[10] - 1e-9 and n1 < n0 - rw[11] else rw[7]
    if r > 0:
        r -= rw[8] * abs(heading)
    return r


@njit(**_INLINE)
def controller(onehot, u, singletons, dd, strength):  # pragma: no cover - compiled
    """``SituationFCS.output(u)``: the centre of gravity of the rules' headings."""
    a = singletons.size
    total = label_strengths(onehot, u, strength)
    if total <= 0.0:
        return _pairwise_sum(singletons, a) / a
    return dd(a, strength.ctypes.data, 1, singletons.ctypes.data, 1) / total


def probe(readings: np.ndarray, fc: np.ndarray, ids: np.ndarray, c: int, fp: np.ndarray,
          ip: np.ndarray, lp: Any, onehot: np.ndarray, singletons: np.ndarray, q: np.ndarray,
          tau: float, relative: bool, rng: np.random.Generator, m: float, m_power: int
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]:
    """What ``sitframe.runs.fused`` compares with the components' own before a trial runs
    compiled: the (n, c) memberships of the (n, d) ``readings`` over the centres ``fc``
    (scattered to their ``ids``) and the (n,) :func:`controller` outputs, the (c,)
    :func:`_softmax` draws of ``q``, ``memberships[0] @ q.max(axis=1)`` (the value of the next
    situation) and the centres' memberships of the first reading to the power ``m`` (the
    on-line update's), each from the compiled kernels a trial runs (called from Python: their
    types are the trial's)."""
    n, d = fc.shape
    a = singletons.size
    u, heads = np.zeros((readings.shape[0], c)), np.empty(readings.shape[0])
    feat, diff, d2, ua, strength = np.empty(d), np.empty(fc.shape), np.empty(n), np.empty(n), \
        np.empty(a)
    ptrs, dims, strides, scalar = np.empty(3, np.intp), np.empty(1, np.intp), \
        np.empty(3, np.intp), np.empty(1)
    ev, none = np.zeros(len(EV), np.int64), np.empty(0)  # (fixed centres: the fcm's)
    ev[_CHECK] = 1
    fc, ids = np.ascontiguousarray(fc, dtype=np.float64), np.asarray(ids, dtype=np.int64)
    um = np.empty(0)
    for k in range(readings.shape[0]):
        row = np.empty(c)
        situate(np.array(readings[k]), fc, np.empty(n), ids, fp, ip, ev, np.zeros(len(EVF)),
                feat, diff, d2, ua, np.empty(n), row, none, none, none, np.empty(0, np.int64),
                lp.log, lp.power, ptrs, dims, strides, scalar)
        if k == 0:
            um = ua.copy()
            _power(um, m, m_power, lp.power[0], lp.power[1], lp.power[2], ptrs, dims, strides,
                   scalar)
        u[k] = row
        heads[k] = controller(onehot, row, singletons, lp.ddot, strength)
    choice = np.empty(c, dtype=np.int64)
    _softmax(q, tau, relative, rng, lp.exp, np.empty(c * a), choice)
    vmax = np.ascontiguousarray(np.maximum.reduce(q, axis=1))
    return u, heads, choice, float(lp.ddot(c, u[0].ctypes.data, 1, vmax.ctypes.data, 1)), um


def _warm() -> None:
    """Load (or, the first time, compile) the kernels now, with the types a trial passes
    (``sitframe.runs.fused`` hands every array over C-contiguous, writable but the world's
    segments and the substep times): run at import, as :mod:`sitframe.sim.kernels_numba`
    does."""
    lp = numpy_loops.loops()
    if isinstance(lp, str):
        return
    c, a, d, L = 2, 3, 2, 1
    seg, times = np.array([[0.0], [1.0], [1.0], [0.0], [1.0]]), np.linspace(0.0, 1.5, 31)
    seg.setflags(write=False)  # (as a world's packed segments and the substep times)
    times.setflags(write=False)
    fp = np.array([3.0, 0.15, 0.1, 5.0, 1e-60, 0.3, 0.9, 0.3, 1.0, 1.0, 0.0, 0.0, 0.15])
    rp = np.array([0.15, 100.0, 1.5, 0.1, 0.3, 90.0, 0.05, 45.0, 1.0])
    ip = np.array([1, 1, 0, 1, 1, 5, 50, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1])
    ev = np.zeros(len(EV), np.int64)
    ev[_CHECK] = 1
    ints = [np.zeros(c, np.int64) for _ in range(4)]
    rng = np.random.default_rng(0)
    state = np.array([-1, 0, 0, 0, 1, 0, 0])
    f2 = [np.zeros((L, k)) for k in (3, d, c, 2)]
    run(L, False, np.zeros(3), False, np.zeros(2), seg, times, rp, np.zeros(12),
        np.zeros(1, np.int64), np.zeros(1), np.zeros(d), np.ones((c, d)), np.ones(c),
        np.arange(c), ev, np.zeros(len(EVF)), np.zeros(d), np.zeros(d), np.zeros(d),
        ints[3], np.zeros(c), np.zeros(c), np.zeros((c, d)), np.ones(a),
        np.zeros((c, a)), np.ones(2), np.zeros((c, 2)), np.zeros((c, a)), ints[0],
        np.zeros((c, a), np.int64), ints[1], ints[2], np.zeros((L, c), np.int8), np.zeros(c),
        np.zeros(c, np.bool_), fp, ip, state, np.array([0.5, 0.5, 0.0, 0.0, 0.0] + [0.0] * 6),
        np.zeros(d), np.zeros(c), np.zeros(d), np.zeros(c), rng, lp.log, lp.power,
        lp.exp, lp.ddot, np.zeros((L + 1, 3)), f2[1], f2[2], f2[3],
        np.zeros(L), np.zeros(L, np.bool_), np.zeros((L, 2)), np.zeros(L),
        np.zeros(L, np.int64), np.zeros((L, c), np.int64), np.zeros((L, c), np.int64),
        np.zeros((L, c, a)))
    probe(np.ones((1, d)), np.ones((c, d)), np.arange(c), c, fp, ip, lp, np.zeros((c, a)),
          np.ones(a), np.ones((c, a)), 1.0, True, rng, 1.2, 0)


_warm()
