"""Pioneer 2DX simulator: a differential-drive disc in a world of thin walls.

Five lines from a notebook::

    from sitframe.sim.world import load_world
    from sitframe.sim.robot import Simulator, Command
    from sitframe.plugins.sonar import SonarRing
    sim = Simulator(load_world("training"), sensor=SonarRing(), seed=1)
    reading, info = sim.reset(); reading, outcome = sim.step(Command(30.0, 0.15))

Motion model
------------
A :class:`Command` is a *relative* heading change (degrees, positive = left /
counter-clockwise, clipped to [-90, 90]) and a speed (m/s, clipped to
[``min_speed``, ``max_speed``]). During one control period (1.5 s) the robot
moves at the commanded speed while turning toward ``theta + heading_change``
at the turn-rate limit (100 deg/s), then drives straight: an exact circular
arc followed by a straight segment (unicycle model, integrated in closed form).

Collisions
----------
The disc's clearance to every wall and obstacle edge is checked at every
substep (50 ms; at 0.30 m/s a substep moves 15 mm, a tenth of the radius, so a
zero-thickness wall cannot be jumped). Segments that cannot be reached during
the period are discarded first (one distance test from the start), so a step
in open space costs no substep checks at all. When a substep's clearance drops
below the radius, the contact is refined between the last free substep and
that one (two rounds of 16-fold subdivision, ~0.1 mm at top speed); the robot
*stalls* at the last free refined pose, touching but never inside the wall,
and the remaining time of the period is lost.

Recovery
--------
The thesis says only that after a collision the robot "retracts slightly back
and forth, adjusting its heading relative to the position of the obstacle it
collided with". We implement that explicitly (``RobotParams.recovery``):

``"backoff-turn"`` (default)
    1. back off ``recovery_backoff_m`` (0.05 m) along the contact normal (from
       the contact point through the disc centre), stopping short of anything
       else it would touch;
    2. rotate on the spot by ``recovery_turn_deg`` (45 deg) in the direction
       that turns the front away from the contact point (never past facing
       straight away from it). A dead-ahead contact picks the side with ``rng``.
``"none"``
    stall at the contact pose.

Everything that happened is in the :class:`StepOutcome`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from sitframe.params import choice_field, number
from sitframe.sim import geometry as geo
from sitframe.sim.fastinit import record
from sitframe.sim.kernels import contact, fused, kernels

if TYPE_CHECKING:  # (a world is read through its segments and start pose only)
    from sitframe.sim.world import World

__all__ = ["Command", "RobotParams", "Simulator", "StepOutcome", "packed_params", "step_robot",
           "trajectory"]

_REFINE = 16  # subdivisions per refinement round
_BACKOFF_SAMPLES = 11


@dataclass(frozen=True)
class RobotParams:
    """Physical and control parameters of the simulated robot.

    A run's config sets them in its ``[robot]`` table (same names); the checks below are
    the ones that table's values go through.

    Attributes
    ----------
    radius
        Disc radius [m] (Pioneer 2DX as simulated in the thesis: 0.30 m diameter).
    max_turn_rate_deg_s
        Turn-rate limit [deg/s].
    control_period_s
        How long one command is held [s].
    substep_s
        Collision-check interval [s].
    min_speed, max_speed
        Commanded speeds are clipped to this range [m/s].
    max_heading_change_deg
        Commanded heading changes are clipped to ±this [deg].
    recovery
        ``"backoff-turn"`` or ``"none"`` (see the module docstring).
    recovery_backoff_m
        Back-off distance after a collision [m].
    recovery_turn_deg
        Turn away from the contact after backing off [deg].
    """

    radius: float = 0.15
    max_turn_rate_deg_s: float = 100.0
    control_period_s: float = 1.5
    substep_s: float = 0.05
    min_speed: float = 0.10
    max_speed: float = 0.30
    max_heading_change_deg: float = 90.0
    recovery: Literal["backoff-turn", "none"] = "backoff-turn"
    recovery_backoff_m: float = 0.05
    recovery_turn_deg: float = 45.0

    def __post_init__(self) -> None:
        number("radius", self.radius, lo=0.0, lo_open=True, unit="m")
        number("max_turn_rate_deg_s", self.max_turn_rate_deg_s, lo=0.0, lo_open=True, unit="deg/s")
        number("control_period_s", self.control_period_s, lo=0.0, lo_open=True, unit="s")
        number("substep_s", self.substep_s, lo=0.0, lo_open=True, unit="s")
        number("min_speed", self.min_speed, lo=0.0, unit="m/s")
        number("max_speed", self.max_speed, lo=0.0, lo_open=True, unit="m/s")
        number("max_heading_change_deg", self.max_heading_change_deg, lo=0.0, hi=180.0, unit="deg")
        choice_field(self, "recovery")
        number("recovery_backoff_m", self.recovery_backoff_m, lo=0.0, unit="m")
        number("recovery_turn_deg", self.recovery_turn_deg, lo=0.0, hi=180.0, unit="deg")
        if self.min_speed > self.max_speed:
            raise ValueError(
                f"min_speed ({self.min_speed}) must be <= max_speed ({self.max_speed})"
            )
        if self.substep_s > self.control_period_s:
            raise ValueError(
                f"substep_s ({self.substep_s}) must be <= control_period_s "
                f"({self.control_period_s})"
            )
        if self.max_speed * self.substep_s > 0.5 * self.radius:
            raise ValueError(
                f"substep_s too long: at max_speed the robot moves "
                f"{self.max_speed * self.substep_s:g} m per substep; expected at most half the "
                f"radius ({0.5 * self.radius:g} m) so thin walls cannot be jumped"
            )


@record
class Command:
    """One control command, held for ``control_period_s``.

    Attributes
    ----------
    heading_change_deg
        Relative heading change [deg], positive = left (CCW); clipped to
        ±``max_heading_change_deg`` (90) when executed.
    speed_m_s
        Speed [m/s]; clipped to [``min_speed``, ``max_speed``] when executed.
    """

    heading_change_deg: float
    speed_m_s: float = 0.15

    def __post_init__(self) -> None:
        h, s = self.heading_change_deg, self.speed_m_s
        if h.__class__ is float and s.__class__ is float and h - h == 0.0 and s - s == 0.0:
            return  # two finite floats (the loop's case, made every iteration)
        for name in ("heading_change_deg", "speed_m_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float | np.number):
                raise TypeError(f"Command.{name} must be a number, got {type(v).__name__} {v!r}")
            if not math.isfinite(v):
                raise ValueError(f"Command.{name} must be finite, got {v!r}")


@record
class StepOutcome:
    """What happened during one control period.

    Attributes
    ----------
    pose_before
        (3,) pose at the start: x [m], y [m], theta [rad].
    pose
        (3,) final pose, after any recovery; theta wrapped to [-pi, pi].
    collided
        Whether the disc touched a wall or obstacle edge.
    contact_xy
        (2,) contact point [m] on the wall, NaN if no collision.
    contact_pose
        (3,) pose at which the disc touched (is ``pose`` if no collision).
    distance_m
        Forward path length travelled under the command [m] (up to the
        contact; the back-off is in ``backoff_m``).
    heading_change_deg
        Heading change achieved by the command [deg] (before any recovery turn).
    backoff_m
        Distance backed off during recovery [m] (0 without collision).
    recovery_turn_deg
        Heading change of the recovery turn [deg] (0 without collision).
    """

    pose_before: np.ndarray
    pose: np.ndarray
    collided: bool
    contact_xy: np.ndarray
    contact_pose: np.ndarray
    distance_m: float
    heading_change_deg: float
    backoff_m: float = 0.0
    recovery_turn_deg: float = 0.0


_NAN2 = np.full(2, np.nan)
_NAN2.setflags(write=False)
_TIMES_CACHE: dict[tuple[float, float], np.ndarray] = {}


def _times(period: float, substep: float) -> np.ndarray:
    key = (period, substep)
    t = _TIMES_CACHE.get(key)
    if t is None:
        n = max(1, math.ceil(period / substep - 1e-9))
        t = np.linspace(0.0, period, n + 1)
        t.setflags(write=False)
        _TIMES_CACHE[key] = t
    return t


def _plan(pose: np.ndarray, command: Command, params: RobotParams
          ) -> tuple[float, float, float, float, float, float]:
    """Return x0, y0, th0, v, omega [rad/s] and turn duration t_turn [s]."""
    x0, y0, th0 = float(pose[0]), float(pose[1]), float(pose[2])
    if x0 - x0 != 0.0 or y0 - y0 != 0.0 or th0 - th0 != 0.0:  # (not finite: inf - inf is NaN)
        raise ValueError(f"pose must be 3 finite numbers (x, y, theta_rad), got {pose!r}")
    # min(max(value, lo), hi) as Python's min and max choose (b if b > a else a, b if b < a
    # else a), written out: this runs every iteration
    lo, hi, h = -params.max_heading_change_deg, params.max_heading_change_deg, \
        float(command.heading_change_deg)
    h = lo if lo > h else h
    dh = math.radians(hi if hi < h else h)
    lo, hi, v = params.min_speed, params.max_speed, float(command.speed_m_s)
    v = lo if lo > v else v
    v = hi if hi < v else v
    w = math.radians(params.max_turn_rate_deg_s)
    t_turn, period = abs(dh) / w, params.control_period_s
    t_turn = period if period < t_turn else t_turn
    omega = math.copysign(w, dh) if dh != 0.0 else 0.0
    return x0, y0, th0, v, omega, t_turn


def _poses_at(t: np.ndarray, x0: float, y0: float, th0: float, v: float, omega: float,
              t_turn: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form arc-then-straight poses at times ``t`` (arrays x, y, theta)."""
    th_end = th0 + omega * t_turn
    kern = kernels()
    if kern is not None:  # the same arithmetic around numpy's sin and cos (sitframe.sim.kernels)
        buf = np.empty((5, t.size))
        kern.arc_angles(t, th0, omega, t_turn, buf[0], buf[1])
        kern.arc_poses(t, np.array((x0, y0, th0, v, omega, t_turn, math.cos(th_end),
                                    math.sin(th_end))),
                       buf[0], np.sin(buf[0]), np.cos(buf[1]), np.sin(buf[1]), buf[2:])
        return buf[2], buf[3], buf[4]
    tt = np.minimum(t, t_turn)
    half = (0.5 * omega) * tt
    # chord of the arc = v * tt * sin(half) / half, along th0 + half
    chord = (v * tt) * np.sinc(half * (1.0 / math.pi))
    ang = th0 + half
    ts = v * (t - tt)
    x = x0 + chord * np.cos(ang) + ts * math.cos(th_end)
    y = y0 + chord * np.sin(ang) + ts * math.sin(th_end)
    return x, y, th0 + omega * tt


def _pose_at(t: float, x0: float, y0: float, th0: float, v: float, omega: float,
             t_turn: float) -> tuple[float, float, float]:
    """Scalar version of :func:`_poses_at` (pure Python, for the fast path)."""
    tt = t_turn if t_turn < t else t  # (min(t, t_turn), as Python's min chooses)
    half = 0.5 * omega * tt
    chord = v * tt * (math.sin(half) / half if half != 0.0 else 1.0)
    th_end = th0 + omega * t_turn
    ts = v * (t - tt)
    return (x0 + chord * math.cos(th0 + half) + ts * math.cos(th_end),
            y0 + chord * math.sin(th0 + half) + ts * math.sin(th_end),
            th0 + omega * tt)


def trajectory(pose: np.ndarray, command: Command, params: RobotParams,
               times: np.ndarray) -> np.ndarray:
    """Collision-free poses the command would produce at ``times`` (for tests and plots).

    Parameters
    ----------
    pose
        (3,) start pose x [m], y [m], theta [rad].
    command
        The command.
    params
        Robot parameters.
    times
        (n,) times since the start [s], within [0, control_period_s].

    Returns
    -------
    numpy.ndarray
        (n, 3) poses, ignoring walls.
    """
    x0, y0, th0, v, omega, t_turn = _plan(np.asarray(pose, dtype=float), command, params)
    x, y, th = _poses_at(np.asarray(times, dtype=float), x0, y0, th0, v, omega, t_turn)
    return np.stack([x, y, th], axis=1)


def packed_params(params: RobotParams) -> np.ndarray:
    """``params`` as the compiled kernels read them (``sitframe.sim.kernels_numba.ROBOT``):
    a (9,) float array, the recovery as 1.0 (``"backoff-turn"``) or 0.0 (``"none"``).
    Made once per parameters object and kept on it (it runs every step): do not change it."""
    got = params.__dict__.get("_packed")
    if got is None:
        got = np.array([params.radius, params.max_turn_rate_deg_s, params.control_period_s,
                        params.min_speed, params.max_speed, params.max_heading_change_deg,
                        params.recovery_backoff_m, params.recovery_turn_deg,
                        params.recovery == "backoff-turn"], dtype=np.float64)
        object.__setattr__(params, "_packed", got)  # (frozen: its fields do not change)
    return got


def outcome_from(pose_before: np.ndarray, out: np.ndarray, collided: bool,
                 params: RobotParams) -> StepOutcome:
    """The :class:`StepOutcome` of a compiled step's figures ``out``
    (:func:`sitframe.sim.kernels_numba.step_contact`'s first twelve), as :func:`step_robot`
    builds it (the end pose *is* the contact pose of a step that touched nothing, or of one
    that stalled: recovery ``"none"``). Its arrays are views of ``out``, which is the
    caller's to give away."""
    final = out[:3]
    if not collided:
        return StepOutcome(pose_before, final, False, _NAN2, final, out.item(8), out.item(9))
    if params.recovery == "none":
        return StepOutcome(pose_before, final, True, out[3:5], final, out.item(8),
                           out.item(9))
    return StepOutcome(pose_before, final, True, out[3:5], out[5:8], out.item(8), out.item(9),
                       out.item(10), out.item(11))


def _wrap(theta: float) -> float:
    return math.remainder(theta, 2.0 * math.pi)


def step_robot(
    world: World,
    pose: np.ndarray,
    command: Command,
    params: RobotParams,
    rng: np.random.Generator,
) -> StepOutcome:
    """Execute one command for ``params.control_period_s`` with collision handling.

    Parameters
    ----------
    world
        The world (its cached :attr:`~sitframe.sim.world.World.segment_set` is used).
    pose
        (3,) start pose x [m], y [m], theta [rad]. It should be free (clearance
        ≥ radius); a start already inside a wall counts as an immediate
        collision and the robot only backs off.
    command
        Heading change and speed (clipped to the robot's limits).
    params
        Robot parameters.
    rng
        Randomness (only used to break the tie of a dead-ahead contact).

    Returns
    -------
    StepOutcome
        Final pose, collision flag, contact point/pose, distance and turn.
    """
    T = params.control_period_s
    pose_before = pose if isinstance(pose, np.ndarray) else np.asarray(pose, dtype=float)
    whole = contact()
    if whole is not None and pose_before.shape == (3,) and pose_before.dtype == np.float64:
        x0, y0, th0 = pose_before.tolist()  # (the whole step in one call, but a dead-ahead
        # contact, whose turn's side is drawn below)
        if x0 - x0 != 0.0 or y0 - y0 != 0.0 or th0 - th0 != 0.0:
            _plan(pose, command, params)  # (raises: not finite)
        out = np.empty(14)
        code = whole.robot_step(x0, y0, th0, float(command.heading_change_deg),
                                float(command.speed_m_s), packed_params(params),
                                _times(T, params.substep_s), world.segment_set.packed, True,
                                out)
        if code != whole.TIE:
            return outcome_from(pose_before, out, code != whole.FREE, params)
    plan = _plan(pose, command, params)
    x0, y0, th0, v, omega, t_turn = plan
    r = params.radius
    path = v * T
    reach = path + r + params.recovery_backoff_m + 1e-9
    fast = fused()
    if fast is not None:  # steps 1 and 2 below in one call, when nothing is touched
        end = np.empty(3)
        if not fast.step_free(x0, y0, th0, v, omega, t_turn, _times(T, params.substep_s),
                              world.segment_set.packed, reach * reach, r * r, end):
            x, y, th = float(end[0]), float(end[1]), float(end[2])
            final = np.array([x, y, _wrap(th)])
            return StepOutcome(pose_before, final, False, _NAN2, final, path,
                               math.degrees(th - th0))
    # --- 1. which segments can the swept disc (or the back-off) reach at all?
    near = _near(world.segment_set, x0, y0, reach)
    if near is None:  # open space: nothing to hit, pure-Python closed form
        x, y, th = _pose_at(T, *plan)
        final = np.array([x, y, _wrap(th)])
        return StepOutcome(pose_before, final, False, _NAN2, final, path,
                           math.degrees(th - th0))

    # --- 2. all substeps against the near segments at once
    times = _times(T, params.substep_s)
    xs, ys, ths = _poses_at(times, *plan)
    r2 = r * r
    k = _first_contact(xs, ys, near, r2)
    if k < 0:
        final = np.array([xs[-1], ys[-1], _wrap(float(ths[-1]))])
        return StepOutcome(pose_before, final, False, _NAN2, final, path,
                           math.degrees(float(ths[-1]) - th0))

    # --- 3. refine the contact between the last free substep and the first bad one
    if k == 0:  # started inside: no forward motion
        t_c, cx, cy, cth = 0.0, x0, y0, th0
    else:
        j = k - 1
        t_c, cx, cy, cth = float(times[j]), float(xs[j]), float(ys[j]), float(ths[j])
        hi = float(times[k])
        for _ in range(2):
            ts = _linspace(t_c, hi, _REFINE + 1)
            fx, fy, fth = _poses_at(ts, *plan)
            j = _first_contact(fx, fy, near, r2)  # first bad sample; ts[0] is free
            if j < 0:
                j = _REFINE  # the bad end of the interval
            if j == 0:  # cannot happen (ts[0] was free); keep the known free pose
                break
            hi = float(ts[j])
            j -= 1  # the last free sample: the disc touches there
            t_c, cx, cy, cth = float(ts[j]), float(fx[j]), float(fy[j]), float(fth[j])
    contact_xy = _nearest_point(cx, cy, near)
    backoff, bx, by = 0.0, cx, cy
    if params.recovery != "none" and params.recovery_backoff_m > 0.0:
        # --- 4. recovery: back off along the contact normal, then turn away (_turn_away);
        # started inside (k == 0): accept any back-off that does not get closer to a wall
        nx, ny = _normal(cx, cy, cth, contact_xy)
        backoff, bx, by = _backoff(cx, cy, nx, ny, params.recovery_backoff_m, near, r2, k == 0)
    return _turn_away(pose_before, plan, t_c, (cx, cy, cth), contact_xy, (backoff, bx, by),
                      params, rng)


def _normal(cx: float, cy: float, cth: float, contact_xy: np.ndarray) -> tuple[float, float]:
    """The unit contact normal, from the contact point through the disc centre ``(cx, cy)``."""
    nx, ny = cx - float(contact_xy[0]), cy - float(contact_xy[1])
    norm = math.hypot(nx, ny)
    if norm > 0.0:
        return nx / norm, ny / norm
    # centre on the wall (only if it started there): back straight up
    return -math.cos(cth), -math.sin(cth)


def _turn_away(pose_before: np.ndarray, plan: tuple[float, ...], t_c: float,
               contact: tuple[float, float, float], contact_xy: np.ndarray,
               backed: tuple[float, float, float], params: RobotParams,
               rng: np.random.Generator) -> StepOutcome:
    """The end of :func:`step_robot` for a robot that touched a wall at time ``t_c`` [s] at
    pose ``contact`` (x, y, theta), at the point ``contact_xy``, and backed off
    ``backed`` = (distance [m], x, y): turn away from the contact (a dead-ahead contact picks
    the side with ``rng``)."""
    cx, cy, cth = contact
    backoff, bx, by = backed
    contact_pose = np.array([cx, cy, _wrap(cth)])
    heading_change = math.degrees(cth - plan[2])
    distance = plan[3] * t_c
    if params.recovery == "none":
        return StepOutcome(pose_before, contact_pose, True, contact_xy, contact_pose,
                           distance, heading_change)
    bearing = _wrap(math.atan2(float(contact_xy[1]) - by, float(contact_xy[0]) - bx) - cth)
    turn_max = math.radians(params.recovery_turn_deg)
    room = math.pi - abs(bearing)  # turning more would face the contact again
    turn = min(turn_max, room)
    if bearing > 0.0:
        turn = -turn
    elif bearing == 0.0 and rng.random() < 0.5:
        turn = -turn
    final = np.array([bx, by, _wrap(cth + turn)])
    return StepOutcome(pose_before, final, True, contact_xy, contact_pose, distance,
                       heading_change, backoff, math.degrees(turn))


# Each helper below runs the compiled kernel (sitframe.sim.kernels) when there is one and
# the numpy code otherwise; both give the same numbers.


def _near(segs: geo.SegmentSet, x: float, y: float, reach: float) -> geo.SegmentSet | None:
    """The segments closer than ``reach`` to ``(x, y)``, or None if there are none."""
    if segs.n == 0:
        return None
    kern = kernels()
    if kern is not None:
        idx = np.empty(segs.n, dtype=np.intp)
        m = kern.near_segments(x, y, segs.packed, reach * reach, idx)
        return segs.subset(idx[:m]) if m else None  # (open space: no subset, no slice)
    idx = np.flatnonzero(_dist2_cols(np.array([x]), np.array([y]), segs)[0] < reach * reach)
    return segs.subset(idx) if idx.size else None


def _first_contact(xs: np.ndarray, ys: np.ndarray, near: geo.SegmentSet, r2: float) -> int:
    """The first of the (n,) points ``xs, ys`` where the disc (radius² ``r2``) touches, or -1."""
    kern = kernels()
    if kern is not None:
        return int(kern.first_contact(xs, ys, near.packed, r2))
    bad = (_dist2_cols(xs, ys, near) < r2).any(axis=1)
    k = int(bad.argmax())
    return k if bad[k] else -1


def _linspace(start: float, stop: float, num: int) -> np.ndarray:
    """``numpy.linspace(start, stop, num)``."""
    kern = kernels()
    if kern is None:
        return np.linspace(start, stop, num)
    out = np.empty(num)
    kern.linspace(start, stop, out)
    return out


def _nearest_point(x: float, y: float, near: geo.SegmentSet) -> np.ndarray:
    """(2,) the point of the segments nearest ``(x, y)`` (the contact point)."""
    kern = kernels()
    if kern is not None:
        return np.array(kern.nearest_point(x, y, near.packed))
    return geo.nearest_on_segments(np.array([[x, y]]), near)[2][0]


def _backoff(cx: float, cy: float, nx: float, ny: float, length: float, near: geo.SegmentSet,
             r2: float, inside: bool) -> tuple[float, float, float]:
    """Back off up to ``length`` from ``(cx, cy)`` along ``(nx, ny)`` while the disc is free.

    ``inside``: the disc started inside a wall; then any sample no closer to a wall
    than the first is free. Returns (distance backed off, x, y).
    """
    kern = kernels()
    if kern is not None:
        s = np.empty(_BACKOFF_SAMPLES)
        m, x, y = kern.backoff(cx, cy, nx, ny, length, near.packed, r2, inside, s)
        return (float(s[m]), x, y) if m > 0 else (0.0, cx, cy)
    s = np.linspace(0.0, length, _BACKOFF_SAMPLES)
    bx, by = cx + s * nx, cy + s * ny
    d2b = _dist2_cols(bx, by, near).min(axis=1)
    ok = d2b >= (np.minimum(d2b[0], r2) - 1e-15 if inside else r2)
    m = int(np.count_nonzero(np.logical_and.accumulate(ok))) - 1
    return (float(s[m]), float(bx[m]), float(by[m])) if m > 0 else (0.0, cx, cy)


def _dist2_cols(xs: np.ndarray, ys: np.ndarray, s: geo.SegmentSet) -> np.ndarray:
    """(n,) points against s → (n, S) squared distances."""
    return geo._dist2(xs[:, None], ys[:, None], s)


class Simulator:
    """One robot in one world, with a Gymnasium-like ``reset`` / ``step``.

    Parameters
    ----------
    world
        The world.
    params
        Robot parameters.
    sensor
        Anything with ``read(world, pose, rng) -> reading`` (e.g. the
        ``pioneer-sonar`` plugin), or None for no readings.
    seed
        Seed of :attr:`rng` (None → fresh OS entropy; pass a seed to reproduce).

    Attributes
    ----------
    world, params, sensor
        As given.
    pose
        (3,) current pose x [m], y [m], theta [rad].
    rng
        The :class:`numpy.random.Generator` used by the sensor and the robot.
    """

    def __init__(self, world: World, *, params: RobotParams | None = None,
                 sensor: Any = None, seed: int | None = None):
        if not hasattr(world, "segment_set") or not hasattr(world, "start"):
            raise TypeError(f"world must be a sitframe World (load_world), got "
                            f"{type(world).__name__}")
        self.world = world
        self.params = RobotParams() if params is None else params
        self.sensor = sensor
        self.rng = np.random.default_rng(seed)
        self.pose = world.start.copy()

    def reset(self, *, seed: int | None = None, pose: np.ndarray | None = None
              ) -> tuple[np.ndarray | None, dict[str, Any]]:
        """Put the robot at ``pose`` (default: the world's start) and read the sensor.

        Parameters
        ----------
        seed
            Re-seed :attr:`rng` when given.
        pose
            (3,) x [m], y [m], theta [rad]; must be free for the robot disc.

        Returns
        -------
        reading, info
            The sensor reading (None without a sensor) and ``{"pose": pose}``.
        """
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if pose is None:
            p = self.world.start.copy()
        else:
            p = np.array(pose, dtype=np.float64).reshape(-1)
            if p.shape != (3,) or not np.all(np.isfinite(p)):
                raise ValueError(f"pose must be 3 finite numbers (x, y, theta_rad), got {pose!r}")
            if not self.world.is_free(p[None, :2], self.params.radius)[0]:
                raise ValueError(
                    f"pose {p.tolist()} is not free for a robot of radius {self.params.radius} m "
                    "(inside or touching a wall or obstacle, or outside the walls)"
                )
        self.pose = p
        return self._read(), {"pose": self.pose.copy()}

    def step(self, command: Command) -> tuple[np.ndarray | None, StepOutcome]:
        """Execute ``command`` for one control period; return (reading, outcome)."""
        out = step_robot(self.world, self.pose, command, self.params, self.rng)
        self.pose = out.pose
        return self._read(), out

    def _read(self) -> np.ndarray | None:
        if self.sensor is None:
            return None
        return self.sensor.read(self.world, self.pose, self.rng)
