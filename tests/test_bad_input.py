"""Bad-input corpus through the CLI (issue 8, item 1).

Every case runs a ``sitframe`` command on one bad input in a fresh working
directory and asserts that it is rejected cleanly: exit status 2, stderr is
exactly one line starting ``sitframe: error:`` that names the file (and the
key, where there is one), no traceback anywhere, and nothing written (the
working directory and the input files are unchanged: no ``logs/`` folder, no
output file, no modified log). Most cases call :func:`sitframe.cli.app.main`
in-process; :func:`test_real_command_has_no_traceback` runs the installed
``sitframe`` command in subprocesses.

Real logs come from one tiny run (2 collection rooms, c = 6, 4 FCM trials,
100 iterations, 1 trial) in a module-scoped fixture; the damaged logs are
made from it (cut in half, bytes overwritten in the middle, attributes or
groups deleted). Cases marked "regression" failed with a traceback, a wrong
error type or a written file before the fix named in the commit history.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import pytest
from helpers import ROOM, small_config

from sitframe.cli.app import main

SMALL = small_config(trials=1, iterations=100, eval_iterations=50)

WORLD = ROOM + """
[goal]
position = [5, 1]
radius = 0.3
"""


def _sub(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


def _cfg(old: str, new: str) -> str:
    return _sub(SMALL, old, new)


def _world(old: str, new: str) -> str:
    return _sub(WORLD, old, new)


# ----------------------------------------------------------------------------- fixture: logs


def _edit(src: Path, dst: Path, fn) -> None:
    shutil.copyfile(src, dst)
    with h5py.File(dst, "a") as f:
        fn(f)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with a real log, damaged copies of it, and a good world file."""
    d = tmp_path_factory.mktemp("bad-input")
    (d / "small.toml").write_text(SMALL)
    (d / "room.toml").write_text(WORLD)
    log = d / "small.h5"
    cwd = os.getcwd()
    try:
        os.chdir(d)
        assert main(["run", "small.toml", "--out", str(log), "--workers", "1", "--json"]) == 0
    finally:
        os.chdir(cwd)
    data = log.read_bytes()
    (d / "truncated.h5").write_bytes(data[: len(data) // 2])
    mid = len(data) // 2
    corrupt = bytearray(data)
    corrupt[mid - 2048: mid + 2048] = b"\xff" * 4096
    (d / "corrupted.h5").write_bytes(bytes(corrupt))
    head = bytearray(data)
    head[100:400] = b"\0" * 300
    (d / "corrupted-header.h5").write_bytes(bytes(head))
    (d / "text.h5").write_text("this is not an HDF5 file\n")
    (d / "empty.h5").write_bytes(b"")
    with h5py.File(d / "foreign.h5", "w") as f:
        f.attrs["creator"] = "someone else"
        f.create_dataset("x", data=[1, 2, 3])
    _edit(log, d / "v99.h5", lambda f: f.attrs.__setitem__("schema_version", 99))

    def no_trials(f: h5py.File) -> None:
        del f["trials"]
        del f["summary"]
        f.create_group("trials")
    _edit(log, d / "no-trials.h5", no_trials)
    _edit(log, d / "no-situations.h5", lambda f: f.__delitem__("cluster"))
    _edit(log, d / "no-config.h5", lambda f: f.attrs.__delitem__("config"))
    _edit(log, d / "bad-config.h5", lambda f: f.attrs.__setitem__("config", "[[[ not toml"))
    _edit(log, d / "bad-worlds.h5", lambda f: f.attrs.__setitem__("worlds", "{not json"))
    _edit(log, d / "no-policy.h5", lambda f: f.__delitem__("trials/0000/behaviours"))
    _edit(log, d / "bad-state.h5", lambda f: f.__delitem__("cluster/state/centers"))
    _edit(log, d / "no-trial-attr.h5", lambda f: f["trials/0000"].attrs.__delitem__("seed"))

    def unfinished_bad_state(f: h5py.File) -> None:
        del f["cluster/state/centers"]
        del f["trials/0000"]
        f.attrs["status"] = "running"
    _edit(log, d / "unfinished-bad-state.h5", unfinished_bad_state)
    (d / "not-utf8.toml").write_bytes(b"\xff\xfe[experiment]\n")
    return d


# ----------------------------------------------------------------------------- the corpus


@dataclass
class Case:
    """One bad input: the command, files to create in the working directory, and what the
    error line must contain (``{D}`` in argv and ``must`` is the fixture folder)."""

    id: str
    argv: list[str]
    must: list[str]
    files: dict[str, str | bytes] = field(default_factory=dict)


def case(id: str, argv: str | list[str], *must: str, **files: str | bytes) -> Case:
    argv = argv.split() if isinstance(argv, str) else argv
    return Case(id, argv, list(must), {k.replace("__", "."): v for k, v in files.items()})


RUN = "run c.toml"

CASES = [
    # ---- run configs: syntax, types, values ---------------------------------------------
    case("config-malformed-toml", RUN, "c.toml", "not valid TOML", c__toml="[experiment\n"),
    case("config-empty", RUN, "c.toml", "config is empty", c__toml=""),
    case("config-whitespace", RUN, "c.toml", "config is empty", c__toml="  \n\n\t\n"),
    case("config-not-utf8", "run {D}/not-utf8.toml", "not-utf8.toml", "cannot read config"),
    case("config-binary", RUN, "c.toml", "not valid TOML", c__toml="\x00\x01\x02"),
    case("config-duplicate-table", RUN, "c.toml", "not valid TOML",
         c__toml=SMALL + "\n[experiment]\nname = 'x'\n"),
    case("config-section-not-table", RUN, "c.toml: experiment:", "expected a table",
         c__toml="experiment = 3\n[behaviours.avoid]\ncomponent = 'fuzzy-q'\n"),
    case("config-wrong-type", RUN, "c.toml: experiment.trials:", "got str 'x'",
         c__toml=_cfg("trials = 1", "trials = 'x'")),
    case("config-bool-for-int", RUN, "c.toml: interpreter.c:", "expected an integer",
         c__toml=_cfg("c = 6", "c = true")),
    case("config-nan", RUN, "c.toml: experiment.default_speed:", "non-finite",
         c__toml=_cfg("seed = 3", "seed = 3\ndefault_speed = nan")),
    case("config-inf", RUN, "c.toml: collect.rate_hz:", "non-finite inf",
         c__toml=_cfg('worlds = ["collect-1", "collect-2"]',
                      'worlds = ["collect-1"]\nrate_hz = inf')),
    case("config-param-nan", RUN, "c.toml: behaviours.avoid.alpha:", "non-finite nan",
         c__toml=_cfg("p = 5", "p = 5\nalpha = nan")),
    case("config-param-minus-inf", RUN, "c.toml: robot.radius:", "non-finite",
         c__toml=SMALL + "\n[robot]\nradius = -inf\n"),
    case("config-list-of-wrong-type", RUN, "c.toml: collect.worlds[0]:", "expected a name",
         c__toml=_cfg('worlds = ["collect-1", "collect-2"]', "worlds = [1]")),
    # ---- unknown keys and names (with a did-you-mean / the available names) -------------
    case("config-unknown-section", RUN, "c.toml: experimnt:", "did you mean 'experiment'",
         c__toml=SMALL.replace("[experiment]", "[experimnt]")),
    case("config-unknown-key", RUN, "c.toml: experiment.trails:", "did you mean 'trials'",
         c__toml=_cfg("trials = 1", "trails = 1")),
    case("config-goal-pairs-typo-in-a-plain-run", RUN, "c.toml: goal.pairs:", "random",
         c__toml=SMALL + "\n[goal]\npairs = \"randon\"\n"),
    case("config-goal-radius-zero", RUN, "c.toml: goal.radius:", "0",
         c__toml=SMALL + "\n[goal]\nradius = 0\n"),
    case("config-robot-too-big-for-start", RUN, "c.toml: robot.radius:", "does not fit",
         c__toml=SMALL + "\n[robot]\nradius = 1.2\n"),
    case("config-robot-too-big-for-a-wander-start", RUN, "c.toml: robot.radius:",
         "does not fit at the start pose of world 'collect-1'",
         c__toml=_sub(SMALL, "[collect]\n", "[collect]\nmode = \"wander\"\n")
         + "\n[robot]\nradius = 0.9\n"),
    case("config-unknown-robot-key", RUN, "c.toml: robot.radus:", "did you mean 'radius'",
         c__toml=SMALL + "\n[robot]\nradus = 0.2\n"),
    case("config-unknown-param", RUN, "c.toml: behaviours.avoid.alhpa:",
         "did you mean 'alpha'", c__toml=_cfg("p = 5", "p = 5\nalhpa = 0.3")),
    case("config-unknown-reward-param", RUN, "c.toml: behaviours.avoid.reward_params.colision:",
         "did you mean 'collision'",
         c__toml=_cfg("p = 5", "p = 5\nreward_params = {colision = -30}")),
    case("regression-arbiter-reward-params-not-a-table", RUN, "c.toml: arbiter.reward_params:",
         "expected a table", c__toml=SMALL + "\n[arbiter]\nreward_params = 3\n"),  # traceback
    case("regression-reward-params-without-reward", RUN,  # were silently ignored
         "c.toml: arbiter.reward_params:", "reward_params without a reward",
         c__toml=SMALL + "\n[arbiter]\ncomponent = 'single'\nreward_params = {collision = 1}\n"),
    case("regression-policy-from-in-the-sensor-table", RUN, "c.toml: sensor.policy_from:",
         "the sensor table takes no 'policy_from' (only behaviours do)",
         c__toml=SMALL + "\n[sensor]\npolicy_from = {log = 'x.h5'}\n"),
    case("config-missing-file", "run nope.toml", "nope.toml: config file not found"),
    case("preset-unknown", "run obstacle-avoid", "unknown experiment 'obstacle-avoid'",
         "did you mean 'obstacle-avoidance", "available presets:", "speed"),
    case("component-unknown-behaviour", RUN, "c.toml: behaviours.avoid:",
         "unknown behaviour 'fuzzy-qq'", "did you mean 'fuzzy-q'", "available: crisp-q, fuzzy-q",
         c__toml=_cfg('component = "fuzzy-q"', 'component = "fuzzy-qq"')),
    case("component-unknown-reward", RUN, "c.toml: behaviours.avoid.reward:",
         "unknown reward 'obstacle'", "available: goal-progress, obstacle-avoidance",
         c__toml=_cfg('reward = "obstacle-avoidance"', 'reward = "obstacle"')),
    case("component-unknown-arbiter", RUN, "c.toml: arbiter:", "did you mean 'cdb'",
         "available: cdb", c__toml=SMALL + "\n[arbiter]\ncomponent = 'cbd'\n"),
    case("component-unknown-sensor", RUN, "c.toml: sensor:", "available: laser, pioneer-sonar",
         c__toml=SMALL + "\n[sensor]\ncomponent = 'sonar'\n"),
    case("component-unknown-interpreter", RUN, "c.toml: interpreter:", "available: evolving, fcm",
         c__toml=_cfg('component = "fcm"', 'component = "kmeans"')),
    case("world-unknown-in-config", RUN, "c.toml: experiment.world:",
         "unknown world 'trainng'", "did you mean 'training'", "novel-1",
         c__toml=_cfg("seed = 3", 'seed = 3\nworld = "trainng"')),
    case("world-unknown-option", "run {D}/small.toml --world narnia", "error: --world: ",
         "unknown world 'narnia'", "training"),  # (was blamed on small.toml's key)
    case("world-missing-file-in-config", RUN, "nope.toml", "world file not found",
         "training", c__toml=_cfg("seed = 3", 'seed = 3\nworld = "nope.toml"')),
    case("run-out-empty", ["run", "{D}/small.toml", "--out", ""], "--out",
         "expected the path of the log to write, got ''"),  # wrote logs/small.h5 instead
    case("run-trials-zero", "run {D}/small.toml --trials 0", "--trials", "[1, "),
    case("policy-from-missing-log", RUN, "missing.h5: log file not found",
         c__toml=_cfg("p = 5", "p = 5\npolicy_from = {log = 'missing.h5'}")),
    case("plugins-dir-missing", RUN, "nodir", "does not exist",
         c__toml=SMALL + "\n[plugins]\ndirs = ['nodir']\n"),
    case("plugin-syntax-error", "--plugins-dir pl plugins", "pl/p.py:1", "syntax error",
         **{"pl/p.py": "def oops(:\n"}),
    case("plugin-component-raises", "--plugins-dir pl run c.toml", "plugin p (pl/p.py)",
         "creating arbiter 'boom'", "RuntimeError: kaboom",
         c__toml=SMALL + "\n[arbiter]\ncomponent = 'boom'\n",
         **{"pl/p.py": "from sitframe import hookimpl\nclass Boom:\n    name = 'boom'\n"
                       "    def __init__(self):\n        raise RuntimeError('kaboom')\n"
                       "@hookimpl\ndef sitframe_arbiters():\n    return [Boom]\n"}),
    # regressions: these wrote a log or escaped as tracebacks before the fixes
    case("regression-stages-without-situations", RUN, "c.toml: experiment.stages:",
         "needs clusters", c__toml=_cfg("seed = 3", 'seed = 3\nstages = ["learn"]')),
    case("regression-collect-world-without-trajectories", RUN, "c.toml: collect.worlds[0]:",
         "no [[trajectories]]",
         c__toml=_cfg('worlds = ["collect-1", "collect-2"]', 'worlds = ["training"]')),
    case("regression-c-above-samples", RUN, "c.toml: interpreter.c:", "fewer than the 5000",
         c__toml=_cfg("c = 6", "c = 5000")),
    case("regression-seed-beyond-int64", RUN, "c.toml: experiment.seed:",
         "9223372036854775807", c__toml=_cfg("seed = 3", "seed = 99999999999999999999999")),
    case("regression-iterations-1e300", RUN, "c.toml: experiment.iterations:", "<= 10000000",
         c__toml=_cfg("iterations = 100", "iterations = 1e300")),
    case("regression-rate-1e300", RUN, "c.toml: collect.rate_hz:", "1e+300",
         c__toml=_cfg('worlds = ["collect-1", "collect-2"]',
                      'worlds = ["collect-1"]\nrate_hz = 1e300')),
    case("regression-tiny-speed", RUN, "c.toml: collect.rate_hz:", "samples",
         c__toml=_cfg('worlds = ["collect-1", "collect-2"]',
                      'worlds = ["collect-1"]\nspeed = 1e-300')),
    case("regression-wander-rate", RUN, "c.toml: collect.rate_hz:", "wander mode",
         c__toml=_cfg('worlds = ["collect-1", "collect-2"]',
                      'worlds = ["collect-1"]\nmode = "wander"\nrate_hz = 1000.0')),
    case("regression-name-with-nul", RUN, "c.toml: experiment.name:", "control characters",
         c__toml=_cfg('name = "small"', 'name = "a\\u0000b"')),
    case("regression-name-escapes-logs", RUN, "c.toml: experiment.name:", "inside logs/",
         c__toml=_cfg('name = "small"', 'name = "../../etc/x"')),
    case("regression-name-absolute", RUN, "c.toml: experiment.name:", "inside logs/",
         c__toml=_cfg('name = "small"', 'name = "/tmp/x"')),
    case("regression-sweep-out-not-a-path", "sweep s.toml", "s.toml: sweep.out:",
         "expected a folder path", s__toml='[sweep]\nbase = "{D}/small.toml"\nout = 3\n'
         '[grid]\n"interpreter.c" = [4]\n'),
    case("regression-sweep-grid-too-large", "sweep s.toml", "s.toml: grid:", "120000 points",
         s__toml='[sweep]\nbase = "{D}/small.toml"\n[grid]\n'
         + "".join(f'"{k}" = [{", ".join(str(v) for v in vs)}]\n' for k, vs in
                   (("experiment.seed", range(50)), ("interpreter.c", range(2, 50)),
                    ("interpreter.trials", range(1, 51))))),
    case("sweep-unknown-key", "sweep s.toml", "s.toml: grid.interpreter.cc:",
         "did you mean 'interpreter.c'",
         s__toml='[sweep]\nbase = "{D}/small.toml"\n[grid]\n"interpreter.cc" = [4]\n'),
    # ---- world files: every world error ---------------------------------------------------
    case("regression-world-key-with-newline", "world show w.toml", "w.toml: robot.a\\nb:",
         "unknown key", w__toml=_world("[robot]", '[robot]\n"a\\nb" = 1')),
    case("world-not-toml", "world show w.toml", "w.toml", "not valid TOML", "line",
         w__toml="name = [\n"),
    case("world-empty", "world show w.toml", "w.toml", "empty", w__toml=""),
    case("world-not-utf8", "world show w.toml", "w.toml", "cannot read world file",
         w__toml=b"\xff\xfename = 'x'\n"),
    case("world-unknown-key", "world show w.toml", "w.toml: nmae:", "did you mean 'name'",
         w__toml=_world('name = "room"', 'nmae = "room"')),
    case("world-unknown-nested-key", "world show w.toml", "w.toml: goal.colour:",
         "expected one of", w__toml=_world("radius = 0.3", "radius = 0.3\ncolour = 'red'")),
    case("world-missing-start", "world show w.toml", "w.toml: robot.start:", "missing",
         w__toml=_world("start = [1.0, 1.0, 90.0]", "")),
    case("world-polygon-2-points", "world show w.toml", "w.toml: obstacles[0].points:",
         "at least 3 points, got 2",
         w__toml=_world("[[4, 2.5], [5, 2.5], [5, 3.2], [4, 3.2]]", "[[4, 2.5], [5, 2.5]]")),
    case("world-self-intersecting-polygon", "world show w.toml",
         "w.toml: obstacles[0].points:", "self-intersecting",
         w__toml=_world("[[4, 2.5], [5, 2.5], [5, 3.2], [4, 3.2]]",
                        "[[4, 2.5], [5, 3.2], [5, 2.5], [4, 3.2]]")),
    case("world-self-intersecting-wall", "world show w.toml", "w.toml: walls[0].points:",
         "self-intersecting",
         w__toml=_world("[[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]",
                        "[[0, 0], [6, 4], [6, 0], [0, 4], [0, 0]]")),
    case("world-non-numeric-coordinate", "world show w.toml",
         "w.toml: walls[0].points[1][0]:", "expected a number",
         w__toml=_world("[6, 0], [6, 4]", '["six", 0], [6, 4]')),
    case("world-nan-coordinate", "world show w.toml", "w.toml: obstacles[0].points[2][1]:",
         "finite", w__toml=_world("[5, 3.2], [4, 3.2]", "[5, nan], [4, 3.2]")),
    case("world-inf-start", "world show w.toml", "w.toml: robot.start[0]:", "finite",
         w__toml=_world("start = [1.0, 1.0, 90.0]", "start = [inf, 1.0, 90.0]")),
    case("world-start-inside-obstacle", "world show w.toml", "w.toml: robot.start:",
         "inside an obstacle",
         w__toml=_world("start = [1.0, 1.0, 90.0]", "start = [4.5, 2.8, 0]")),
    case("world-start-touching-wall", "world show w.toml", "w.toml: robot.start:",
         "robot radius", w__toml=_world("start = [1.0, 1.0, 90.0]", "start = [0.1, 1.0, 0]")),
    case("world-start-touching-obstacle", "world show w.toml", "w.toml: robot.start:",
         "robot radius", w__toml=_world("start = [1.0, 1.0, 90.0]", "start = [3.9, 2.8, 0]")),
    case("world-start-outside-walls", "world show w.toml", "w.toml: robot.start:",
         "outside the walls", w__toml=_world("start = [1.0, 1.0, 90.0]", "start = [8, 1, 0]")),
    case("world-goal-outside-walls", "world show w.toml", "w.toml: goal.position:",
         "outside the walls", w__toml=_world("position = [5, 1]", "position = [9, 1]")),
    case("world-goal-inside-obstacle", "world show w.toml", "w.toml: goal.position:",
         "inside an obstacle", w__toml=_world("position = [5, 1]", "position = [4.5, 3]")),
    case("world-unknown-name", "world show narnia", "unknown world 'narnia'", "training",
         "novel-1"),
    case("world-missing-file", "world show nope.toml", "nope.toml", "world file not found"),
    case("world-bad-in-run", "run {D}/small.toml --world w.toml", "w.toml: robot.start:",
         "outside the walls", w__toml=_world("start = [1.0, 1.0, 90.0]", "start = [8, 1, 0]")),
    case("world-bad-in-evaluate", "evaluate {D}/small.h5 --world w.toml", "w.toml: walls",
         "self-intersecting", w__toml=_world("[[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]",
                                             "[[0, 0], [6, 4], [6, 0], [0, 4], [0, 0]]")),
    # ---- HDF5 logs ------------------------------------------------------------------------
    case("log-missing", "evaluate missing.h5 --world training", "missing.h5: log file not found"),
    case("log-truncated", "evaluate {D}/truncated.h5 --world training", "{D}/truncated.h5",
         "truncated or corrupted"),
    case("log-truncated-analyse", "analyse {D}/truncated.h5 -o out", "{D}/truncated.h5",
         "truncated or corrupted"),
    case("log-corrupted", "evaluate {D}/corrupted.h5 --world training", "{D}/corrupted.h5",
         "corrupted"),
    case("log-corrupted-analyse", "analyse {D}/corrupted.h5 -o out", "{D}/corrupted.h5",
         "corrupted"),
    case("log-corrupted-resume", "run --resume {D}/corrupted.h5", "{D}/corrupted.h5",
         "corrupted"),
    case("log-corrupted-header", "evaluate {D}/corrupted-header.h5 --world training",
         "{D}/corrupted-header.h5", "corrupted"),
    case("log-corrupted-as-clusters-from", RUN, "{D}/corrupted.h5", "corrupted",
         c__toml=_cfg("seed = 3", 'seed = 3\nclusters_from = "{D}/corrupted.h5"')),
    case("log-not-hdf5", "evaluate {D}/text.h5 --world training", "{D}/text.h5",
         "not an HDF5 file"),
    case("log-not-hdf5-analyse", "analyse {D}/text.h5 -o out", "{D}/text.h5",
         "not an HDF5 file"),
    case("log-empty-file", "evaluate {D}/empty.h5 --world training", "{D}/empty.h5",
         "not an HDF5 file"),
    case("log-foreign-hdf5", "run --resume {D}/foreign.h5", "{D}/foreign.h5",
         "not a sitframe log"),
    case("log-unknown-schema", "evaluate {D}/v99.h5 --world training",
         "{D}/v99.h5: schema_version:", "unknown log schema version 99"),
    case("log-unknown-schema-analyse", "analyse {D}/v99.h5 -o out",
         "{D}/v99.h5: schema_version:", "unknown log schema version 99"),
    case("log-no-trials", "evaluate {D}/no-trials.h5 --world training",
         "{D}/no-trials.h5: trials:", "no finished trials"),
    case("log-trial-99", "evaluate {D}/small.h5 --world training --trial 99",
         "{D}/small.h5: trials:", "no trial 99", "[0]"),
    case("log-trial-99-replay", "replay {D}/small.h5 --trial 99 -o out.gif",
         "{D}/small.h5: trials:", "no trial 99"),
    case("log-no-situations", "evaluate {D}/no-situations.h5 --world training",
         "{D}/no-situations.h5: cluster:", "no fitted situations"),
    case("log-no-policy", "evaluate {D}/no-policy.h5 --world training",
         "{D}/no-policy.h5: trials:", "no learned policy"),
    case("log-evaluate-unknown-world", "evaluate {D}/small.h5 --world narnia", "--world",
         "unknown world 'narnia'"),
    case("regression-log-no-config", "evaluate {D}/no-config.h5 --world training",
         "{D}/no-config.h5: config:", "no config"),
    case("regression-log-config-not-toml", "evaluate {D}/bad-config.h5 --world training",
         "{D}/bad-config.h5: config:", "not valid TOML"),
    case("regression-log-config-not-toml-resume", "run --resume {D}/bad-config.h5",
         "{D}/bad-config.h5: config:", "not valid TOML"),
    case("regression-log-worlds-not-json", "analyse {D}/bad-worlds.h5 -o out",
         "{D}/bad-worlds.h5: worlds:", "not valid JSON"),
    case("regression-log-state-missing-centres", "evaluate {D}/bad-state.h5 --world training",
         "{D}/bad-state.h5: cluster/state:", "missing 'centers'"),
    case("regression-log-state-missing-centres-resume",
         "run --resume {D}/unfinished-bad-state.h5 --workers 1",
         "{D}/unfinished-bad-state.h5: cluster/state:", "missing 'centers'"),
    case("regression-log-trial-attr-missing", "evaluate {D}/no-trial-attr.h5 --world training",
         "{D}/no-trial-attr.h5", "cannot read the log", "'seed'"),
    case("regression-evaluate-negative-seed", "evaluate {D}/small.h5 --world training --seed -1",
         "--seed:", "expected an integer in [0, inf), got -1"),
    case("regression-analyse-missing-trial", "analyse {D}/small.h5 --trial 5 -o out",
         "{D}/small.h5: --trial:", "no trial(s) [5]"),
    case("regression-run-out-unwritable", "run {D}/small.toml --workers 1 --out "
         "{D}/small.toml/x.h5", "{D}/small.toml/x.h5: --out:", "cannot create the log"),
    case("regression-world-show-out-unwritable", "world show training -o {D}/small.toml/x.png",
         "{D}/small.toml/x.png: -o:", "cannot write the picture"),
    case("regression-evaluate-iterations-huge",
         "evaluate {D}/small.h5 --world training --iterations 1000000000000", "--iterations",
         "10000000], got"),
]


def _write_files(c: Case, where: Path, D: str) -> None:
    for name, content in c.files.items():
        path = where / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content.replace("{D}", D))


def _snapshot(*dirs: Path) -> dict[str, tuple[int, int]]:
    """Sizes and times of the files under ``dirs`` (and their names: a new folder shows
    by what it holds). Python's own bytecode caches of an imported plugin folder
    (``__pycache__``, written unless PYTHONDONTWRITEBYTECODE is set) are not output."""
    out = {}
    for d in dirs:
        for p in d.rglob("*"):
            if "__pycache__" in p.parts:
                continue
            st = p.stat()
            out[str(p)] = (st.st_size, st.st_mtime_ns) if p.is_file() else (0, 0)
    return out


def _check_error_line(err: str, must: list[str]) -> None:
    assert "Traceback" not in err, err
    assert err.endswith("\n") and err.count("\n") == 1, f"not one line: {err!r}"
    assert err.startswith("sitframe: error: "), err
    for m in must:
        assert m in err, f"{m!r} not in {err!r}"


@pytest.mark.parametrize("c", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_rejected_cleanly(c: Case, inputs: Path, tmp_path: Path,
                                       monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    D = str(inputs)
    _write_files(c, tmp_path, D)
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("SITFRAME_TRACEBACK", raising=False)
    before = _snapshot(tmp_path, inputs)
    try:
        code = main([a.replace("{D}", D) for a in c.argv])
    except SystemExit as exc:  # argparse-level errors
        code = exc.code
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    _check_error_line(err, [m.replace("{D}", D) for m in c.must])
    assert "Traceback" not in out
    assert _snapshot(tmp_path, inputs) == before, "something was written"
    assert not (tmp_path / "logs").exists()


def test_corpus_size() -> None:
    assert len(CASES) >= 40
    assert len({c.id for c in CASES}) == len(CASES)


SUBPROCESS_CASES = ["config-nan", "world-self-intersecting-polygon", "log-truncated",
                    "log-corrupted", "regression-log-state-missing-centres",
                    "config-unknown-key"]


@pytest.mark.parametrize("cid", SUBPROCESS_CASES)
def test_real_command_has_no_traceback(cid: str, inputs: Path, tmp_path: Path) -> None:
    """The installed ``sitframe`` command: one line on stderr, exit 2, nothing written."""
    exe = shutil.which("sitframe")
    cmd = [exe] if exe else [sys.executable, "-c",
                             "import sys; from sitframe.cli.app import main; sys.exit(main())"]
    c = next(c for c in CASES if c.id == cid)
    D = str(inputs)
    _write_files(c, tmp_path, D)
    before = _snapshot(tmp_path, inputs)
    env = {k: v for k, v in os.environ.items() if k != "SITFRAME_TRACEBACK"}
    proc = subprocess.run(cmd + [a.replace("{D}", D) for a in c.argv], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2, proc.stderr
    _check_error_line(proc.stderr, [m.replace("{D}", D) for m in c.must])
    assert _snapshot(tmp_path, inputs) == before
    assert re.fullmatch(r"sitframe: error: [^\n]+\n", proc.stderr)
