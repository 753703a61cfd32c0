"""The compiled kernels give bit-identical numbers to the numpy code they shadow.

Each test runs the same inputs through both paths -- the numpy one forced by
``numpy_path`` -- and compares with ``numpy.array_equal`` (exact, not close):
a preset's logs must not depend on whether numba is installed.
"""

from __future__ import annotations

import functools
import math
import unittest.mock as mock
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitframe.learning.fcs import SituationFCS
from sitframe.learning.fuzzy_q import FuzzyQLearner, QLearningParams
from sitframe.sim import geometry as geo
from sitframe.sim import kernels
from sitframe.sim.robot import Command, RobotParams, step_robot
from sitframe.sim.world import World, parse_world
from sitframe.situations.events import accumulate_errors
from sitframe.situations.fcm import MembershipFunction, online_update

pytest.importorskip("numba")

K = kernels.load()
if K is None:  # (SITFRAME_NUMBA=0)
    pytest.skip("compiled kernels switched off", allow_module_level=True)


def both(monkeypatch: pytest.MonkeyPatch, fn):  # noqa: ANN001, ANN201 - any callable
    """``(fn() with kernels, fn() with numpy)``."""
    assert kernels.kernels() is K  # (loaded by kernels.load() above)
    fast = fn()
    with monkeypatch.context() as m:
        m.setattr(kernels, "_LOADED", [None])
        slow = fn()
    return fast, slow


exact = st.integers(-4, 4).map(float)  # hits segment ends, parallels, starts on segments
coord = st.one_of(st.floats(-5.0, 5.0, allow_nan=False, width=64), exact)


@st.composite
def segment_sets(draw: st.DrawFn) -> np.ndarray:
    rows = draw(st.lists(st.tuples(coord, coord, coord, coord), min_size=1, max_size=8))
    if draw(st.booleans()):  # a point and an axis-parallel segment
        x, y = draw(exact), draw(exact)
        rows += [(x, y, x, y), (x, y, x + draw(exact), y)]
    return np.array(rows, dtype=float)


@settings(max_examples=80, deadline=None)
@given(segs=segment_sets(), ox=coord, oy=coord,
       angs=st.lists(st.one_of(st.floats(-math.pi, math.pi, width=64),
                               st.sampled_from([0.0, math.pi / 4, math.pi / 2, math.pi])),
                     min_size=1, max_size=6),
       group=st.sampled_from([1, 2]))
def test_ray_casting_is_bit_identical(segs: np.ndarray, ox: float, oy: float, angs: list,
                                      group: int) -> None:
    s = geo.SegmentSet(segs)
    ang = np.array(angs * group)
    ref = geo._raycast(np.array([[ox]]), np.array([[oy]]), np.cos(ang)[:, None],
                       np.sin(ang)[:, None], s, 4.0)
    assert np.array_equal(geo.cast_rays(s, ox, oy, ang, 4.0), ref)
    origins = np.tile([ox, oy], (ang.size, 1))
    assert np.array_equal(geo.raycast(origins, ang, s, 4.0), ref)
    # the range finder's reading: nearest of each group, from a rim of 0.5, clipped or not
    reach = 3.5 + 0.5
    dist = ref.reshape(-1, group).min(axis=1) if group > 1 else ref
    raw = np.where(dist >= reach, 3.5, dist - 0.5)
    # (4.0 = reach: ref doubles as the cast of the range finder's rays)
    assert np.array_equal(geo.rim_ranges(s, ox, oy, ang, 3.5, 0.5, group), raw)
    assert np.array_equal(geo.rim_ranges(s, ox, oy, ang, 3.5, 0.5, group, clip=True),
                          np.clip(raw, 0.0, 3.5))


ROOM = """
name = "room"
[robot]
start = [1, 1, 0.3]
[[walls]]
points = [[0, 0], [5, 0], [5, 4], [0, 4], [0, 0]]
[[walls]]
points = [[2.5, 1], [2.5, 3]]
[[obstacles]]
points = [[3.6, 2.6], [4.2, 2.6], [3.9, 3.2]]
"""


@pytest.fixture(scope="module")
def room() -> World:
    return parse_world(ROOM)


def _wander(world: World, params: RobotParams, poses: list[np.ndarray]) -> list[tuple]:
    """Every field of the outcomes of a fixed, collision-rich sequence of commands."""
    rng = np.random.default_rng(3)
    cmds = rng.uniform([-90.0, 0.1], [90.0, 0.3], (len(poses), 2))
    out = []
    for pose, (turn, speed) in zip(poses, cmds, strict=True):
        o = step_robot(world, pose, Command(float(turn), float(speed)), params, rng)
        out.append((o.pose.tobytes(), o.collided, o.contact_xy.tobytes(),
                    o.contact_pose.tobytes(), o.distance_m, o.heading_change_deg, o.backoff_m,
                    o.recovery_turn_deg))
    return out


@pytest.mark.parametrize("recovery", ["backoff-turn", "none"])
def test_robot_step_is_bit_identical(room: World, recovery: str,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(0)
    # starts all over the room, some touching or inside a wall, headings at random
    xy = rng.uniform([0.05, 0.05], [4.95, 3.95], (300, 2))
    poses = [np.array([x, y, th]) for (x, y), th in zip(xy, rng.uniform(-4, 4, 300),
                                                          strict=True)]
    params = RobotParams(recovery=recovery)
    fast, slow = both(monkeypatch, lambda: _wander(room, params, poses))
    assert fast == slow
    collided = sum(o[1] for o in fast)
    assert 30 < collided < 300  # the contact and recovery paths ran too


def test_a_wall_met_at_any_substep_is_met_on_both_paths(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """The compiled step computes no substep before the robot could reach the nearest wall
    (its path's length so far): robots driving at a wall from every distance that makes the
    first touch fall on each substep, on it to the last bit, or a hair before or after."""
    world = parse_world('name = "w"\n[robot]\nstart = [1, 1, 0]\n'
                        '[[walls]]\npoints = [[0, 0], [12, 0], [12, 6], [0, 6], [0, 0]]\n'
                        '[[walls]]\npoints = [[6, 1], [6, 5]]')
    params = RobotParams()
    r, period = params.radius, params.control_period_s
    starts = []
    for speed in (0.1, 0.15, 0.3):
        for k in range(int(period / params.substep_s) + 2):
            gap = r + speed * k * params.substep_s  # the touch at substep k
            for d in (gap, np.nextafter(gap, 0.0), np.nextafter(gap, 9.0), gap - 1e-7,
                      gap + 1e-7):
                for turn in (0.0, 10.0, -45.0):  # straight at it, and turning away
                    starts.append((np.array([6.0 - d, 3.0, 0.0]), Command(turn, speed)))
    # passing over the inner wall's end (6, 5), the disc grazing it half-way only (a
    # substep, every 7.5 mm, right over it)
    for along in (0.015, 0.03, 0.075, 0.12):
        for h in (r * 0.9, r - 1e-3, r - 1e-6, np.nextafter(r, 0.0)):
            starts.append((np.array([6.0 - along, 5.0 + h, 0.0]), Command(0.0, 0.15)))

    def steps() -> list[tuple]:
        rng = np.random.default_rng(5)
        return [_fields(step_robot(world, p, c, params, rng)) for p, c in starts]

    fast, slow = both(monkeypatch, steps)
    assert fast == slow
    assert 0 < sum(o[2] for o in fast) < len(fast)  # both touching and free steps


def test_a_read_meets_only_the_walls_within_reach_on_both_paths(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled read leaves out the edges farther than 1.01 times its reach: an edge
    across each ray at a distance around the reach (to the last bit, and a hair nearer or
    farther), and edges along rays' lines, read as numpy reads them (every edge tested)."""
    rel = np.radians((np.array([90.0, 50, 30, 10, -10, -30, -50, -90])[:, None]
                      + np.linspace(-12.5, 12.5, 5)[None, :]).reshape(-1))
    reach = 3.0 + 0.15
    dists = (reach, np.nextafter(reach, 0.0), reach - 1e-9, reach + 1e-9, 0.995 * reach,
             1.01 * reach, 2 * reach)
    rng = np.random.default_rng(9)
    hits = 0
    for th in [*rng.uniform(-math.pi, math.pi, 20), *(-rel[:5])]:
        rows = []
        for j, a in enumerate(rel + th):
            c, s_, d = math.cos(a), math.sin(a), dists[j % len(dists)]
            if j % 8 == 7:  # along the ray's line, its near end at d
                rows.append((d * c, d * s_, (d + 1.0) * c, (d + 1.0) * s_))
            else:  # across it, 4 cm long, crossing it at d
                rows.append((d * c - 0.02 * s_, d * s_ + 0.02 * c, d * c + 0.02 * s_,
                             d * s_ - 0.02 * c))
        segs = geo.SegmentSet(np.array(rows))
        fast, slow = both(monkeypatch, lambda th=th, segs=segs: geo.rim_ranges(
            segs, 0.0, 0.0, rel, 3.0, 0.15, 5, clip=True, heading=th))
        assert np.array_equal(fast, slow), th
        hits += int((fast < 3.0).sum())
    assert hits > 20  # the edges inside the reach were met


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), c=st.sampled_from([2, 7, 8, 12, 16, 31]),
       m=st.sampled_from([1.2, 2.0]), on_centre=st.booleans())
def test_memberships_and_controller_are_bit_identical(seed: int, c: int, m: float,
                                                      on_centre: bool) -> None:
    rng = np.random.default_rng(seed)
    centers = rng.uniform(0.0, 3.0, (c, 8))
    x = centers[1].copy() if on_centre else rng.uniform(0.0, 3.0, 8)
    f = MembershipFunction(centers, m)
    u = f(x)
    diff = centers - x
    d2 = np.einsum("ij,ij->i", diff, diff)
    if d2.min() > 0.0:  # the numpy expression of MembershipFunction
        w = np.maximum(d2.min() / d2, f.floor) ** f.p
        ref = w / w.sum()
    else:
        ref = (d2 <= 0.0) / (d2 <= 0.0).sum()
    assert np.array_equal(u, ref)
    singletons = np.array([90.0, 60.0, 30.0, 0.0, -30.0, -60.0, -90.0])
    fcs = SituationFCS(singletons, rng.integers(0, 7, c))
    strength = (fcs._onehot * u[:, None]).max(axis=0)
    assert fcs.output(u) == float(strength @ singletons) / float(strength.sum())


def test_controller_without_rule_strength_gives_the_mean_singleton(
        monkeypatch: pytest.MonkeyPatch) -> None:
    fcs = SituationFCS(np.array([90.0, 0.0, -30.0]), np.array([0, 1, 1]))
    assert both(monkeypatch, lambda: fcs.output(np.zeros(3))) == (20.0, 20.0)
    u = np.array([0.5, 0.25, 0.25])  # labels 0.5 and 0.25: (45 + 0) / 0.75
    assert both(monkeypatch, lambda: fcs.output(u)) == (60.0, 60.0)


def test_pairwise_sum_follows_numpy() -> None:
    rng = np.random.default_rng(1)
    for n in range(1, K.PAIRWISE_MAX + 1):
        a = rng.random(n) ** 9  # magnitudes far apart: the order shows
        w = a.copy()
        K.normalize(w)
        assert np.array_equal(w, a / np.add.reduce(a)), n


def test_linspace_follows_numpy() -> None:
    out = np.empty(17)
    for a, b in [(0.0, 1.5), (0.35, 0.4), (1e-310, 2e-310), (2.0, 2.0), (0.1, 0.0)]:
        K.linspace(a, b, out)
        assert np.array_equal(out, np.linspace(a, b, 17))


def test_rim_ranges_rejects_ragged_groups(room: World) -> None:
    with pytest.raises(ValueError, match="do not make groups of 3"):
        geo.rim_ranges(room.segment_set, 1.0, 1.0, np.zeros(8), 3.0, 0.15, 3)


def _fields(o) -> tuple:  # noqa: ANN001 - a StepOutcome
    return (o.pose_before.tobytes(), o.pose.tobytes(), o.collided, o.contact_xy.tobytes(),
            o.contact_pose.tobytes(), o.distance_m, o.heading_change_deg, o.backoff_m,
            o.recovery_turn_deg)


@pytest.mark.parametrize("recovery", ["backoff-turn", "none"])
def test_fleet_steps_as_step_robot(room: World, recovery: str) -> None:
    from sitframe.sim.fleet import step_robots

    rng = np.random.default_rng(5)
    xy = rng.uniform([0.05, 0.05], [4.95, 3.95], (240, 2))  # some touching or inside a wall
    poses = [np.array([x, y, th]) for (x, y), th in zip(xy, rng.uniform(-4, 4, 240),
                                                          strict=True)]
    cmds = [Command(float(h), float(v)) for h, v in rng.uniform([-90, 0.1], [90, 0.3], (240, 2))]
    cmds[:8] = [Command(0.0, 0.3)] * 8  # the dead-ahead tie is the robot's generator's
    poses[:8] = [np.array([2.5 - 0.2, 2.0, 0.0])] * 8
    params = RobotParams(recovery=recovery)
    ref = [_fields(step_robot(room, p, c, params, np.random.default_rng(i)))
           for i, (p, c) in enumerate(zip(poses, cmds, strict=True))]
    got = []
    for b in range(0, 240, 16):  # a fleet of 16 at a time
        got += [_fields(o) for o in step_robots(room, poses[b:b + 16], cmds[b:b + 16], params,
                                                [np.random.default_rng(i)
                                                 for i in range(b, b + 16)])]
    assert got == ref
    assert 30 < sum(f[2] for f in ref) < 240  # contacts, recoveries and open space all ran
    turns = {f[-1] for f in ref[:8]}
    assert recovery == "none" or turns == {45.0, -45.0}  # both sides of the tie were drawn


def test_rim_ranges_many_rows_are_rim_ranges(room: World,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(2)
    xy = rng.uniform([0.05, 0.05], [4.95, 3.95], (12, 2))
    ang = rng.uniform(-4, 4, (12, 10))
    poses = np.c_[xy, ang[:, 0]]  # (the vector env passes its poses' x, y columns)
    for group, clip in [(1, False), (5, True)]:
        fast, slow = both(monkeypatch, lambda g=group, c=clip: geo.rim_ranges_many(
            room.segment_set, poses[:, :2], ang, 3.0, 0.15, g, clip=c))
        rows = [geo.rim_ranges(room.segment_set, x, y, a, 3.0, 0.15, group, clip=clip)
                for (x, y), a in zip(xy, ang, strict=True)]
        assert np.array_equal(fast, np.stack(rows)) and np.array_equal(slow, fast)


def test_the_first_run_after_an_install_says_why_it_waits(tmp_path, monkeypatch) -> None:
    """On a terminal, a process about to compile the kernels (no numba cache index in the cache
    folder as new as their source) says so in one line; with the cache filled, or off a
    terminal, nothing."""
    import io
    import os

    from numba.core.caching import UserProvidedCacheLocator

    from sitframe.sim import numba_cache

    src = tmp_path / "pkg" / "kernels_numba.py"
    src.parent.mkdir()
    src.write_text("# kernels\n")
    folder = tmp_path / "cache"
    monkeypatch.setattr(numba_cache, "_CONFIGURED", [folder])

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    def said(stream: io.StringIO) -> str:
        monkeypatch.setattr("sys.stderr", stream)
        numba_cache.announce_compilation(src)
        return stream.getvalue()

    assert numba_cache.compile_pending(src, folder)  # no cache yet
    assert said(Terminal()).startswith("sitframe: compiling the simulator's kernels with numba")
    assert said(Terminal()).count("\n") == 1
    bg = Terminal()
    monkeypatch.setattr("sys.stderr", bg)
    numba_cache.announce_compilation(src, background=True)  # (the trial kernel's, elsewhere)
    assert bg.getvalue().startswith("sitframe: compiling the learning trial's kernel in the "
                                    "background") and bg.getvalue().count("\n") == 1
    assert said(io.StringIO()) == ""  # a pipe or a log: never
    sub = folder / UserProvidedCacheLocator.get_suitable_cache_subpath(str(src))
    sub.mkdir(parents=True)
    index = sub / "kernels_numba.cast-40.py311.nbi"
    index.write_bytes(b"")
    t = src.stat().st_mtime
    os.utime(index, (t + 1, t + 1))
    assert not numba_cache.compile_pending(src, folder) and said(Terminal()) == ""
    os.utime(src, (t + 2, t + 2))  # the source changed after the cache was written
    assert numba_cache.compile_pending(src, folder)
    monkeypatch.setattr(numba_cache, "_CONFIGURED", [None])  # no cache: every process compiles
    assert said(Terminal()) == ""


def test_a_cached_kernel_calling_changed_kernels_is_compiled_again(tmp_path) -> None:
    """numba recompiles a cached kernel only when its own file changed; the trial kernel
    calls the simulator's, so its index is dropped when one of those files is newer
    (``numba_cache.drop_stale``), and kept otherwise; other modules' indexes are left."""
    import os

    from numba.core.caching import UserProvidedCacheLocator

    from sitframe.sim import numba_cache

    src, dep = tmp_path / "pkg" / "fused_kernels.py", tmp_path / "pkg" / "kernels_numba.py"
    src.parent.mkdir()
    src.write_text("# trial kernel\n")
    dep.write_text("# simulator kernels\n")
    folder = tmp_path / "cache"
    sub = folder / UserProvidedCacheLocator.get_suitable_cache_subpath(str(src))
    sub.mkdir(parents=True)
    mine, other = sub / "fused_kernels.run-300.py311.nbi", sub / "kernels_numba.cast-40.py311.nbi"
    for p in (mine, other):
        p.write_bytes(b"")
    t = dep.stat().st_mtime
    os.utime(mine, (t + 5, t + 5))
    assert numba_cache.drop_stale(src, dep, folder=folder) == 0 and mine.exists()
    os.utime(dep, (t + 10, t + 10))  # a simulator kernel changed after the index was written
    assert numba_cache.drop_stale(src, dep, folder=folder) == 1
    assert not mine.exists() and other.exists()


def _wait_unlocked(lock: Path, limit: float = 120.0) -> None:
    import time

    end = time.monotonic() + limit
    while True:
        try:
            if lock.read_text() == "failed":
                return
        except FileNotFoundError:
            return
        assert time.monotonic() < end, f"{lock} still held after {limit} s"
        time.sleep(0.05)


def test_a_background_process_compiles_missing_kernels_once(tmp_path, monkeypatch) -> None:
    """The first run after an install: a process of its own compiles a module's kernels into
    the cache (``numba_cache.compile_elsewhere``); while it runs, every caller is told so
    (no second process), even once some of its kernels are cached; once it is done, the
    caller imports them itself."""
    import os

    from numba.core.caching import UserProvidedCacheLocator

    from sitframe.sim import numba_cache

    folder, mods = tmp_path / "cache", tmp_path / "mods"
    folder.mkdir()
    mods.mkdir()
    src = mods / "bg_kernel.py"
    src.write_text("from numba import njit\n\n\n@njit(cache=True)\ndef twice(x):\n"
                   "    return 2 * x\n\n\ntwice(1)\n")
    monkeypatch.setattr(numba_cache, "_CONFIGURED", [folder])
    monkeypatch.setattr(numba_cache, "_TRIED", set())
    monkeypatch.syspath_prepend(str(mods))  # (the background process is given this sys.path)
    started = len(numba_cache._STARTED)
    lock = folder / "bg_kernel.compiling"
    sub = folder / UserProvidedCacheLocator.get_suitable_cache_subpath(str(src))
    sub.mkdir(parents=True)
    index = sub / "bg_kernel.helper-3.py311.nbi"
    index.write_bytes(b"")  # (a kernel the compile in progress has cached: not all of them)
    lock.write_text(str(os.getpid()))  # (a background compile in progress)
    assert "background" in str(numba_cache.compile_elsewhere("bg_kernel", src))
    lock.unlink()
    index.unlink()
    busy = numba_cache.compile_elsewhere("bg_kernel", src)
    assert busy is not None and "background" in busy
    again = numba_cache.compile_elsewhere("bg_kernel", src)
    assert again is not None and "background" in again
    assert len(numba_cache._STARTED) == started + 1  # one background compile per cache folder
    _wait_unlocked(lock)
    assert not lock.exists()
    assert not numba_cache.compile_pending(src, folder)  # compiled into the cache
    assert numba_cache.compile_elsewhere("bg_kernel", src) is None  # now: load it here


def test_a_failed_or_vanished_background_compile_is_not_waited_for(tmp_path,
                                                                  monkeypatch) -> None:
    """A background compile that failed leaves ``failed`` in its lock: the next caller
    compiles the module itself (which shows the error) instead of waiting; one whose process
    is gone without a word (killed) is started again, once per process."""
    import subprocess
    import sys

    from sitframe.sim import numba_cache

    folder, mods = tmp_path / "cache", tmp_path / "mods"
    folder.mkdir()
    mods.mkdir()
    src = mods / "bad_kernel.py"
    src.write_text("raise RuntimeError('no kernels here')\n")
    monkeypatch.setattr(numba_cache, "_CONFIGURED", [folder])
    monkeypatch.setattr(numba_cache, "_TRIED", set())
    monkeypatch.syspath_prepend(str(mods))
    lock = folder / "bad_kernel.compiling"
    with monkeypatch.context() as m:  # (no interpreter to start: compile here, no lock left)
        m.setattr(sys, "executable", "")
        assert numba_cache.compile_elsewhere("bad_kernel", src) is None and not lock.exists()
    assert numba_cache.compile_elsewhere("bad_kernel", src) is not None
    _wait_unlocked(lock)
    assert lock.read_text() == "failed"
    assert numba_cache.compile_elsewhere("bad_kernel", src) is None  # compile here
    assert not lock.exists()
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    monkeypatch.setattr(numba_cache, "_TRIED", set())  # (another process's compile:)
    lock.write_text(gone)  # a compile whose process died
    busy = numba_cache.compile_elsewhere("bad_kernel", src)
    assert busy is not None and gone not in busy.split("pid ")[-1]  # started again
    numba_cache._STARTED[-1].kill()  # ... and this one stopped too: compile here
    numba_cache._STARTED[-1].wait()
    assert numba_cache.compile_elsewhere("bad_kernel", src) is None


def test_the_kernel_cache_lives_in_the_users_cache_folder(tmp_path, monkeypatch) -> None:
    """The cache folder is NUMBA_CACHE_DIR if set, else SITFRAME_CACHE_DIR/numba, else the
    user's cache folder: never the installed package, whose __pycache__ a later editable
    install would turn into a namespace package."""
    from numba.core import config

    from sitframe.sim import numba_cache

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delenv("SITFRAME_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert numba_cache.cache_dir() == tmp_path / "xdg" / "sitframe" / "numba"
    monkeypatch.setenv("SITFRAME_CACHE_DIR", str(tmp_path / "own"))
    assert numba_cache.cache_dir() == tmp_path / "own" / "numba"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba's"))
    assert numba_cache.cache_dir() == tmp_path / "numba's"
    monkeypatch.setattr(numba_cache, "_CONFIGURED", [])
    monkeypatch.setattr(config, "CACHE_DIR", config.CACHE_DIR)
    assert numba_cache.configure() is True
    assert config.CACHE_DIR == str(tmp_path / "numba's") and (tmp_path / "numba's").is_dir()
    package = Path(numba_cache.__file__).parent
    assert not Path(config.CACHE_DIR).resolve().is_relative_to(package.resolve())


def test_an_unwritable_cache_folder_means_no_cache_and_one_warning(tmp_path, monkeypatch,
                                                                  capsys) -> None:
    """A cache folder that cannot be made (here: under a regular file) turns caching off with
    one warning line naming the folder; numba is not pointed anywhere (so it cannot fall
    back into the package either: the kernels' ``cache`` flag is this answer)."""
    from numba.core import config

    from sitframe.sim import numba_cache

    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv("SITFRAME_CACHE_DIR", str(blocker))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(numba_cache, "_CONFIGURED", [])
    monkeypatch.setattr(config, "CACHE_DIR", "")
    assert numba_cache.configure() is False
    assert numba_cache.configure() is False  # asked again: said once
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("sitframe: warning: kernel cache folder ")
    assert str(blocker / "numba") in err and "SITFRAME_CACHE_DIR" in err
    assert config.CACHE_DIR == ""


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), c=st.sampled_from([1, 2, 12, 48]),
       d=st.sampled_from([3, 8]))
def test_evolving_updates_are_bit_identical(seed: int, c: int, d: int) -> None:
    """The evolving interpreter's prototype update and TD-error statistics, compiled and numpy."""
    rng = np.random.default_rng(seed)
    arrays = [rng.uniform(-2.0, 2.0, (c, d)), rng.uniform(1.0, 200.0, c),
              rng.uniform(0.0, 5.0, c), rng.integers(0, 50, c).astype(float),
              rng.uniform(-9.0, 9.0, (c, d))]
    steps = [(rng.uniform(-2.0, 2.0, d), rng.dirichlet(np.ones(c)) ** 1.2,
              np.where(rng.random(c) < 0.2, rng.uniform(0.0, 3.0, c), 0.0)) for _ in range(30)]

    def run() -> list[np.ndarray]:
        F, N, total, count, weighted = (a.copy() for a in arrays)
        for x, um, errors in steps:
            online_update(F, N, F - x, um)
            accumulate_errors(errors, x, total, count, weighted)
        return [F, N, total, count, weighted]

    assert kernels.kernels() is K
    fast = run()
    with mock.patch.object(kernels, "_LOADED", [None]):
        slow = run()
    assert all(np.array_equal(a, b) for a, b in zip(fast, slow, strict=True))
    assert not np.array_equal(fast[0], arrays[0]) and not np.array_equal(fast[2], arrays[2])


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), activation=st.sampled_from([0.0, 0.3]),
       update=st.sampled_from(["thesis", "standard"]), collided=st.booleans())
def test_frozen_rule_td_errors_are_bit_identical(seed: int, activation: float, update: str,
                                                 collided: bool) -> None:
    """The TD errors a converged learner reports to an evolving interpreter, compiled and numpy."""
    rng = np.random.default_rng(seed)
    params = QLearningParams(activation=activation, update=update, terminal_on_collision=True)
    lr = FuzzyQLearner(12, 7, params, rng, 100)
    lr.q = rng.normal(size=(12, 7))
    lr.converged_at, lr.track_td = 1, True
    u0, u1 = rng.dirichlet(np.full(12, 0.3)), rng.dirichlet(np.full(12, 0.3))
    u0.setflags(write=False)
    reward = float(rng.normal())

    def td() -> np.ndarray:
        lr._vmax = None
        lr.update(u0, reward, u1, collided, 5)
        return lr.td_abs.copy()

    fast = td()
    with mock.patch.object(kernels, "_LOADED", [None]):
        slow = td()
    assert np.array_equal(fast, slow)
    assert (fast > 0).sum() == (u0 >= activation).sum() if activation else (fast > 0).all()


def test_the_pioneer_cone_reads_the_same_on_both_paths(room: World,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The sonar kernel casts all rays of a read together (segment by segment, the parallel
    case apart): 8 cones of 5 rays from poses all over the room, some on a wall's line with
    one ray exactly along it), read as the numpy path reads."""
    rng = np.random.default_rng(41)
    rel = np.radians((np.array([90.0, 50, 30, 10, -10, -30, -50, -90])[:, None]
                      + np.linspace(-12.5, 12.5, 5)[None, :]).reshape(-1))
    poses = [(x, y, th) for x, y, th in zip(rng.uniform(-0.5, 5.5, 300),
                                            rng.uniform(-0.5, 4.5, 300),
                                            rng.uniform(-math.pi, math.pi, 300), strict=True)]
    # on a horizontal wall's line with one ray exactly along it (its angle rel + th is 0)
    poses += [(x, y, -rel[k]) for x in (-1.0, 0.0, 1.0, 2.5, 6.0) for y in (0.0, 1.0, 4.0)
              for k in (0, 3, 17, 39)]
    s = room.segment_set
    for x, y, th in poses:
        fast, slow = both(monkeypatch, lambda x=x, y=y, th=th: geo.rim_ranges(
            s, x, y, rel + th, 3.0, 0.15, 5, clip=True))
        assert np.array_equal(fast, slow), (x, y, th)
        fast, slow = both(monkeypatch, lambda x=x, y=y, th=th: geo.cast_rays(s, x, y, rel + th,
                                                                             3.15))
        assert np.array_equal(fast, slow), (x, y, th)
        # relative angles and the heading: the sum, sines and cosines in the compiled call
        fast, slow = both(monkeypatch, lambda x=x, y=y, th=th: geo.rim_ranges(
            s, x, y, rel, 3.0, 0.15, 5, clip=True, heading=th))
        assert np.array_equal(fast, slow), (x, y, th)
        assert np.array_equal(fast, geo.rim_ranges(s, x, y, rel + th, 3.0, 0.15, 5, clip=True))


@settings(max_examples=60, deadline=None)
@given(reading=st.lists(st.one_of(st.floats(-1.0, 5.0, width=64), st.just(math.nan),
                                  st.sampled_from([0.0, 3.0, 1e-320])), min_size=8, max_size=8),
       normalize=st.booleans())
def test_the_gym_observation_is_the_same_on_both_paths(reading: list, normalize: bool) -> None:
    """The env's observation and its nearest range (which the reward reads), NaN included."""
    task = _gym_task(normalize)
    r = np.array(reading)
    with pytest.MonkeyPatch.context() as mp:
        fast, slow = both(mp, lambda: task.observe_nearest(r, np.zeros(3), None))
    assert fast[0].dtype == slow[0].dtype == np.float32
    assert np.array_equal(fast[0], slow[0], equal_nan=True)
    assert fast[1] == slow[1] or math.isnan(fast[1]) and math.isnan(slow[1])


@functools.cache
def _gym_task(normalize: bool):  # noqa: ANN202 - a sitframe.gym.task.Task
    from sitframe.gym.task import Task

    return Task.from_config("obstacle-avoidance", normalize=normalize)


@settings(max_examples=80, deadline=None)
@given(poly=st.lists(st.tuples(coord, coord), min_size=0, max_size=9),
       pts=st.lists(st.tuples(coord, coord), min_size=1, max_size=6))
def test_point_in_polygon_is_the_same_on_both_paths(poly: list, pts: list) -> None:
    """Which points a room's outline or an obstacle holds (every free start pose asks it):
    points on vertices and edges, horizontal edges and degenerate polygons included."""
    p, q = np.array(pts, dtype=float), np.array(poly, dtype=float).reshape(-1, 2)
    with pytest.MonkeyPatch.context() as mp:
        fast, slow = both(mp, lambda: geo.point_in_polygon(p, q))
    assert fast.dtype == slow.dtype == np.bool_
    assert np.array_equal(fast, slow)


@settings(max_examples=80, deadline=None)
@given(segs=segment_sets(), moves=st.lists(st.tuples(coord, coord, coord, coord), min_size=1,
                                           max_size=6),
       radius=st.one_of(st.floats(0.01, 2.0), st.sampled_from([0.5, 1.0])))
def test_clear_moves_are_the_same_on_both_paths(segs: np.ndarray, moves: list,
                                                 radius: float) -> None:
    """Whether a disc moves straight between two points (every shortest path, so every goal
    pair and its SPL, asks it): touching, crossing, zero-length moves and edges included."""
    from sitframe.sim import paths

    world = SimpleNamespace(segments=segs, segment_set=geo.SegmentSet(segs))  # what it reads
    m = np.array(moves, dtype=float)
    with pytest.MonkeyPatch.context() as mp:
        fast, slow = both(mp, lambda: paths._clear_chunk(world, m[:, :2], m[:, 2:], radius))
    assert np.array_equal(fast, slow)


@pytest.mark.parametrize("name", ["goal", "u-trap", "multi-room"])
def test_clear_moves_in_rooms_are_the_same_on_both_paths(monkeypatch: pytest.MonkeyPatch,
                                                         name: str) -> None:
    """Thousands of moves in a room, grazing and crossing walls, as goal pairs ask them."""
    from sitframe.sim import paths
    from sitframe.sim.world import load_world

    world, rng = load_world(name), np.random.default_rng(5)
    x0, y0, x1, y1 = world.bounds
    a = rng.uniform((x0, y0), (x1, y1), (3000, 2))
    b = a + rng.normal(0.0, 1.5, (3000, 2))
    for radius in (0.15, 0.45):
        fast, slow = both(monkeypatch, lambda r=radius: paths._clear_chunk(world, a, b, r))
        assert np.array_equal(fast, slow)
        assert 0.1 < fast.mean() < 0.9  # both kinds of move were asked


def test_the_fused_steps_run_only_where_compiled_sines_are_numpys(
        room: World, monkeypatch: pytest.MonkeyPatch) -> None:
    """A numpy whose sines differ from the C library's (its own vector code) must not get the
    fused steps: the robot then steps and reads through the unfused kernels, the same
    numbers as the fused ones where both agree."""
    assert kernels.fused() is K  # (this machine: numpy's sin and cos are the C library's)
    rng = np.random.default_rng(2)
    xy = rng.uniform([0.05, 0.05], [4.95, 3.95], (200, 2))
    poses = [np.array([x, y, th]) for (x, y), th in zip(xy, rng.uniform(-4, 4, 200),
                                                          strict=True)]
    fused_run = _wander(room, RobotParams(), poses)

    def off_by_one_ulp(x: np.ndarray, out: np.ndarray) -> None:
        out[0], out[1] = np.nextafter(np.sin(x), 2.0), np.cos(x)

    monkeypatch.setattr(kernels, "_TRIG_AGREES", [])
    monkeypatch.setattr(K, "trig", off_by_one_ulp)
    assert kernels.fused() is None
    calls = []
    monkeypatch.setattr(K, "step_free", lambda *a: calls.append(a))
    assert _wander(room, RobotParams(), poses) == fused_run
    assert not calls


def _contact_step(k, world: World, pose: np.ndarray, cmd: Command, params: RobotParams,
                  rng: np.random.Generator) -> tuple:
    """``step_contact``'s outcome as ``step_robot``'s ``StepOutcome`` has it (a dead-ahead
    contact's side drawn from ``rng``, as there)."""
    from sitframe.sim.robot import _times, packed_params

    rp = packed_params(params)
    v, omega, t_turn = k.plan(*(float(p) for p in pose), cmd.heading_change_deg,
                              cmd.speed_m_s, rp)
    out = np.empty(14)
    code = k.step_contact(*(float(p) for p in pose), v, omega, t_turn,
                          np.array(_times(params.control_period_s, params.substep_s)),
                          np.array(world.segment_set.packed), rp, out)
    if code == k.TIE:
        k.finish_turn(out, rng.random() < 0.5)
    return (code != k.FREE, *out[:12])


@pytest.mark.parametrize("params", [RobotParams(), RobotParams(recovery="none"),
                                    RobotParams(recovery_backoff_m=0.0),
                                    RobotParams(recovery_turn_deg=180.0, max_speed=0.3)],
                         ids=["default", "no-recovery", "no-backoff", "half-turn"])
def test_compiled_contact_step_is_step_robots(params: RobotParams) -> None:
    """The whole step compiled (contact, refinement, back-off, turn; the trial's and the Gym
    envs' steps when ``kernels.contact()`` holds) equals ``step_robot`` to the bit, in rooms,
    from poses grazing, facing and inside walls, dead-ahead ties drawn from the generator."""
    k = kernels.contact()
    if k is None:
        pytest.skip("the compiled contact step does not agree with Python's here")
    from sitframe.sim.world import load_world

    rng = np.random.default_rng(11)
    hits = 0
    for name in ("training", "novel-1", "gen:1000003"):
        world = load_world(name)
        segs = world.segment_set.segments
        for i in range(700):
            if i % 7 == 0:  # on a wall, or facing one square on (a dead-ahead contact)
                s = segs[rng.integers(len(segs))]
                f = rng.uniform()
                pose = np.array([s[0] + f * (s[2] - s[0]), s[1] + f * (s[3] - s[1]),
                                 rng.choice([0.0, math.pi / 2, math.pi, -math.pi / 2])])
                if i % 14 == 0:
                    pose[:2] += rng.normal(0.0, 0.2, 2)
            else:
                pose = world.random_free_pose(rng, params.radius, margin=0.0)
                pose[2] = rng.uniform(-math.pi, math.pi)
            cmd = Command(float(rng.choice([0.0, rng.uniform(-120, 120)])),
                          float(rng.uniform(0.05, 0.35)))
            seed = int(rng.integers(2**32))
            ref = step_robot(world, pose, cmd, params, np.random.default_rng(seed))
            got = _contact_step(k, world, pose, cmd, params, np.random.default_rng(seed))
            want = (ref.collided, *ref.pose, *ref.contact_xy, *ref.contact_pose,
                    ref.distance_m, ref.heading_change_deg, ref.backoff_m,
                    ref.recovery_turn_deg)
            assert np.array_equal(np.array(got, float), np.array(want, float), equal_nan=True), \
                (name, i, pose, cmd)
            hits += bool(ref.collided)
    assert hits > 300  # (most of these steps touch a wall)


def test_compiled_hypot_and_wrap_are_pythons() -> None:
    k = kernels.contact()
    if k is None:
        pytest.skip("the compiled contact step does not agree with Python's here")
    rng = np.random.default_rng(3)
    ab = rng.normal(size=(2, 20000)) * 10.0 ** rng.uniform(-320, 300, (2, 20000))
    ab[:, :5000] = rng.normal(size=(2, 5000))
    ab[0, 5000:5010], ab[1, 5005:5015] = np.inf, np.nan
    got = np.array([k.hypot(a, b) for a, b in ab.T])
    want = np.array([math.hypot(a, b) for a, b in ab.T])
    assert np.array_equal(got, want, equal_nan=True)
    th = np.concatenate([rng.uniform(-100, 100, 20000), ab[0, :5000], math.pi * np.arange(-40, 41),
                         math.pi / 2 * np.arange(-40, 41), [0.0, -0.0, 5e-324, -5e-324, 1e300]])
    wrapped = np.array([k.wrap(x) for x in th])
    exact = np.array([math.remainder(x, 2 * math.pi) for x in th])
    assert wrapped.tobytes() == exact.tobytes()  # (the sign of a zero too)
