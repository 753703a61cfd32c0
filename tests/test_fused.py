"""The compiled learning trial (sitframe.runs.fused) writes the log the Python loop writes.

Each configuration below runs twice, compiled and with ``SITFRAME_FUSED=0``, and the two
logs must hold the same bits; the compiled run must really have been compiled (the kernel's
driver is counted), and a trial that cannot be compiled must say why and take the loop.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sitframe.cli import main as cli_main
from sitframe.contract.config import to_toml
from sitframe.logs.compare import log_contents
from sitframe.runs import fused

pytest.importorskip("numba", reason="the compiled trial needs numba")

BASE: dict[str, Any] = {
    "experiment": {"name": "fused", "seed": 3, "trials": 1, "iterations": 700,
                   "world": "training", "default_speed": 0.15,
                   "stages": ["collect", "cluster", "learn", "evaluate"]},
    "sensor": {"component": "pioneer-sonar"},
    "collect": {"mode": "wander", "wander_samples": 60, "worlds": ["collect-1", "collect-2"]},
    "interpreter": {"component": "fcm", "c": 6, "trials": 2},
    "behaviours": {"avoid": {"component": "fuzzy-q", "reward": "obstacle-avoidance",
                             "headings": [90, 60, 30, 0, -30, -60, -90], "b": 3, "p": 30}},
    "arbiter": {"component": "single"},
    "evaluate": {"worlds": ["training", "novel-1"], "iterations": 150},
}

EVOLVING = {"interpreter.component": "evolving", "interpreter.transform": "log",
            "interpreter.m": 1.2}

#: Variations of BASE, each a dotted key (or a table) -> value; together they take every
#: branch of the kernel: transforms and exact powers, both update rules, soft-max modes and
#: annealing, learning-rate schedule, collision as terminal, convergence guards, tie-breaks,
#: every rule updated, cones of rays, a chain of rooms, a robot and a speed of their own, the
#: thesis's reward settings and the wall-following reward; evolving situations (every answer
#: of the kernel: ``test_evolving_trials_hand_python_what_only_it_does``).
CASES: dict[str, dict[str, Any]] = {
    "thesis": {},
    "log-cones-standard": {"interpreter.transform": "log", "interpreter.m": 1.2,
                           "sensor.beam_width_deg": 25, "sensor.rays_per_beam": 5,
                           "behaviours.avoid.update": "standard",
                           "behaviours.avoid.terminal_on_collision": True,
                           "behaviours.avoid.q_init_value": 250.0,
                           "behaviours.avoid.temperature_mode": "absolute",
                           "behaviours.avoid.temperature": 2.0,
                           "behaviours.avoid.min_updates": 5,
                           "behaviours.avoid.reward_params": {"heading_cost": 0.3}},
    "inverse-square-annealed": {"interpreter.transform": "inverse", "interpreter.m": 1.5,
                                "behaviours.avoid.temperature_decay": 0.99,
                                "behaviours.avoid.temperature_min": 0.05,
                                "behaviours.avoid.alpha_visits": 20,
                                "behaviours.avoid.tie_break": "centre",
                                "behaviours.avoid.activation": 0.0},
    "m2-random-q": {"interpreter.m": 2.0, "behaviours.avoid.q_init": "random",
                    "behaviours.avoid.q_init_spread": 5.0, "behaviours.avoid.p": 3,
                    "behaviours.avoid.b": 1},
    "rooms": {"experiment.rooms": ["gen:1000000", "gen:1000001", "gen:1000002"],
              "experiment.episode_iterations": 130, "collect.worlds": ["gen:1000000"],
              "interpreter.transform": "log"},
    "speed-and-robot": {"experiment.default_speed": 0.22,
                        "robot": {"radius": 0.17, "recovery_turn_deg": 60.0,
                                  "recovery_backoff_m": 0.04, "max_turn_rate_deg_s": 80.0}},
    # Evolving situations: the main preset's shape (a chain of rooms, cones of rays, the
    # checks once due at an episode's first reading); splits, prunes, a growth limit and the
    # situations frozen with the rules; fixed prototypes and every id used (refused); and
    # situations grown from nothing (no cluster stage).
    "evolving-rooms": {**EVOLVING, "interpreter.capacity": 24, "interpreter.merge_distance": 0.8,
                       "experiment.iterations": 1500, "interpreter.check_every": 132,
                       "experiment.rooms": ["gen:1000000", "gen:1000001", "gen:1000002"],
                       "experiment.episode_iterations": 130, "collect.worlds": ["gen:1000000"],
                       "sensor.beam_width_deg": 25, "sensor.rays_per_beam": 5,
                       "behaviours.avoid.update": "standard",
                       "behaviours.avoid.terminal_on_collision": True,
                       "behaviours.avoid.q_init_value": 250.0,
                       "behaviours.avoid.min_updates": 20,
                       "behaviours.avoid.reward_params": {"heading_cost": 0.3}},
    "evolving-split-prune-freeze": {**EVOLVING, "interpreter.transform": "inverse",
                                    "interpreter.m": 1.5, "interpreter.capacity": 16,
                                    "interpreter.prune_after": 150,
                                    "interpreter.split_ratio": 1.5,
                                    "interpreter.split_min_updates": 20,
                                    "interpreter.freeze_with_rules": True,
                                    "interpreter.grow_until": 900, "interpreter.check_every": 30,
                                    "interpreter.create_distance": 1.0,
                                    "behaviours.avoid.activation": 0.0, "behaviours.avoid.p": 5,
                                    "behaviours.avoid.b": 2, "experiment.iterations": 1500},
    "evolving-range-fixed": {**EVOLVING, "interpreter.transform": "range", "interpreter.m": 2.0,
                             "interpreter.capacity": 8, "interpreter.adapt": False,
                             "interpreter.create_distance": 0.5, "interpreter.create_after": 2,
                             "behaviours.avoid.p": 8, "experiment.iterations": 1200},
    "evolving-from-nothing": {**EVOLVING, "experiment.stages": ["learn", "evaluate"],
                              "interpreter.capacity": 20, "experiment.iterations": 1000},
    "wall-following": {"experiment.world": "wall-following", "interpreter.transform": "inverse",
                       "behaviours.avoid.reward": "wall-following",
                       "behaviours.avoid.reward_params": {"near": 0.15, "far": 0.35},
                       "behaviours.avoid.headings": [90, 60, 40, 20, 0, -20, -40, -60, -90],
                       "evaluate.worlds": ["wall-following"]},
}


def _config(changes: dict[str, Any]) -> dict[str, Any]:
    cfg = {k: dict(v) if isinstance(v, dict) else v for k, v in BASE.items()}
    cfg["behaviours"] = {"avoid": dict(BASE["behaviours"]["avoid"])}
    for key, value in changes.items():
        if "." not in key:
            cfg[key] = value
            continue
        *path, last = key.split(".")
        box = cfg
        for p in path:
            box = box[p]
        box[last] = value
    return cfg


def _run(tmp: Path, name: str, cfg: dict[str, Any], monkeypatch: pytest.MonkeyPatch,
         compiled: bool) -> tuple[dict[str, Any], int]:
    """Run ``cfg``; its log's contents and how many trials ran compiled."""
    monkeypatch.setenv("SITFRAME_FUSED", "wait" if compiled else "0")
    calls = []
    real = fused.run
    monkeypatch.setattr(fused, "run", lambda *a, **k: calls.append(1) or real(*a, **k))
    path = tmp / f"{name}-{int(compiled)}.toml"
    path.write_text(to_toml(cfg))
    out = tmp / f"{name}-{int(compiled)}.h5"
    assert cli_main(["run", str(path), "--out", str(out)]) == 0
    contents = {k: v for k, v in log_contents(out).items()
                if not k.startswith(("code_hash", "created", "config", "run_", "elapsed"))}
    return contents, len(calls)


def _bits(v: Any) -> tuple[str, tuple[int, ...], bytes]:
    a = np.asarray(v)
    return a.dtype.str, a.shape, repr(a.tolist()).encode() if a.dtype.kind == "O" else \
        a.tobytes()


def _differ(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """The keys whose values are not the same bits in both logs."""
    return [k for k in sorted(set(a) | set(b)) if k not in a or k not in b or
            _bits(a[k]) != _bits(b[k])]


@pytest.mark.parametrize("case", sorted(CASES))
def test_compiled_trial_writes_the_python_loops_log(case: str, tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Both paths, the contact compiled too (``contact``) or stepped in Python between
    calls (every other case): the same bits."""
    if sorted(CASES).index(case) % 2:
        monkeypatch.setattr(fused, "contact", lambda: None)
    cfg = _config(CASES[case])
    compiled, n_compiled = _run(tmp_path, case, cfg, monkeypatch, True)
    python, n_python = _run(tmp_path, case, cfg, monkeypatch, False)
    # (the learning trial and its evaluations, the frozen protocol's runs)
    assert n_compiled == 1 + len(cfg["evaluate"]["worlds"]) and n_python == 0
    assert not _differ(compiled, python)
    assert any(k.endswith("heading/q_snapshots") for k in compiled)  # (it learned)
    if case.startswith("evolving"):  # (its situations changed)
        assert np.asarray(compiled["trials/0000/situations/events/kind"]).size


def test_evolving_trials_hand_python_what_only_it_does(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """An evolving trial runs compiled, and the kernel hands Python each kind of iteration it
    leaves to the interpreter and the tracker: a first reading and a next reading that create
    or check, events to deliver after learning, and steps that touch a wall."""
    from sitframe.runs import fused_kernels as fk

    codes: list[int] = []

    class Counted:
        def __getattr__(self, name: str) -> Any:
            return getattr(fk, name)

        def run(self, *args: Any) -> int:
            codes.append(fk.run(*args))
            return codes[-1]

    monkeypatch.setattr(fused, "_compiled", Counted)
    monkeypatch.setattr(fused, "contact", lambda: None)
    _run(tmp_path, "evolving", _config(CASES["evolving-rooms"]), monkeypatch, True)
    assert {fk.DONE, fk.NEED_STEP, fk.NEED_FIRST, fk.NEED_NEXT, fk.NEED_SYNC} <= set(codes)
    assert codes.count(fk.NEED_NEXT) < 1500 // 20  # (the kernel does the rest itself)


def test_a_trial_with_a_step_observer_or_a_noisy_sensor_runs_the_python_loop(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    noisy = _config({"sensor.noise_std": 0.01, "experiment.iterations": 500})
    _contents, n = _run(tmp_path, "noisy", noisy, monkeypatch, True)
    assert n == 0
    plugin = tmp_path / "plugins"
    plugin.mkdir()
    (plugin / "watch.py").write_text(
        "from sitframe import hookimpl\nSEEN = []\n\n@hookimpl\n"
        "def sitframe_step(record):\n    SEEN.append(record.transition.before.iteration)\n")
    path = tmp_path / "watched.toml"
    path.write_text(to_toml(_config({"experiment.iterations": 500})))
    calls: list[bool] = []
    real = fused.run
    monkeypatch.setenv("SITFRAME_FUSED", "wait")
    monkeypatch.setattr(fused, "run", lambda *a, **k: calls.append(a[2].learn) or real(*a, **k))
    assert cli_main(["--plugins-dir", str(plugin), "run", str(path), "--out",
                     str(tmp_path / "w.h5")]) == 0
    assert calls == [False, False]  # (its evaluations only: the hook is not called in them)


def test_trials_run_the_python_loop_while_the_kernel_compiles_in_the_background(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The first run after an install: the trial kernel is not in the cache and a process
    of its own compiles it; the trials meanwhile run the Python loop (the same log as
    ``SITFRAME_FUSED=0``) instead of waiting, and run compiled once it is cached."""
    import os
    import sys

    from sitframe.sim import numba_cache

    folder = tmp_path / "cache"
    folder.mkdir()
    (folder / "sitframe.runs.fused_kernels.compiling").write_text(str(os.getpid()))  # (alive)
    monkeypatch.setattr(numba_cache, "_CONFIGURED", [folder])  # (an empty cache)
    monkeypatch.delitem(sys.modules, "sitframe.runs.fused_kernels", raising=False)  # (not yet)
    cfg = _config({"experiment.iterations": 600})
    background, n = _run(tmp_path, "bg", cfg, monkeypatch, False)
    monkeypatch.setenv("SITFRAME_FUSED", "1")
    assert "compiling in the background" in str(fused._compiled())
    calls: list[int] = []
    real = fused.run
    monkeypatch.setattr(fused, "run", lambda *a, **k: calls.append(1) or real(*a, **k))
    path = tmp_path / "bg.toml"
    path.write_text(to_toml(cfg))
    assert cli_main(["run", str(path), "--out", str(tmp_path / "bg-1.h5")]) == 0
    assert calls == [] and "sitframe.runs.fused_kernels" not in sys.modules
    contents = {k: v for k, v in log_contents(tmp_path / "bg-1.h5").items()
                if not k.startswith(("code_hash", "created", "config", "run_", "elapsed"))}
    assert not _differ(contents, background)
    monkeypatch.undo()  # (the user's cache again: the kernel loaded, or compiled here)
    monkeypatch.setenv("SITFRAME_FUSED", "wait")
    assert not isinstance(fused._compiled(), str)


def test_a_subclass_that_changes_a_step_is_not_compiled() -> None:
    from sitframe.plugins.sonar import SonarRing

    class Shifted(SonarRing):
        name = "shifted-sonar"

        def read(self, world: Any, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
            return super().read(world, pose, rng) * 0.5

    assert SonarRing(rays_per_beam=3, beam_width_deg=20)._fused() is not None
    assert Shifted()._fused() is None
    assert SonarRing(dropout=0.1)._fused() is None

    from sitframe.plugins.arbiters import SingleArbiter
    from sitframe.plugins.fuzzy_q import CrispQBehaviour, FuzzyQBehaviour
    from sitframe.plugins.rewards import ObstacleAvoidanceReward

    class Louder(ObstacleAvoidanceReward):
        def __call__(self, tr: Any) -> float:
            return 2.0 * super().__call__(tr)

    assert ObstacleAvoidanceReward()._fused() is not None
    assert ObstacleAvoidanceReward(progress=1.0)._fused() is None  # (it keeps poses)
    assert Louder()._fused() is None
    rng = np.random.default_rng(0)
    beh, crisp, fast = FuzzyQBehaviour(), CrispQBehaviour(), FuzzyQBehaviour(
        speeds=[0.1, 0.2], learn=["heading", "speed"])
    for b in (beh, crisp, fast):
        b.reset(rng, 4, 10)
    assert beh._fused() is not None
    assert crisp._fused() is None and fast._fused() is None  # (its own propose; a speed)
    assert SingleArbiter()._fused() == {}

    class Hushed(FuzzyQBehaviour):  # (reports no TD errors to evolving situations)
        def situation_errors(self) -> None:
            return None

    hushed = Hushed()
    hushed.reset(rng, 4, 10)
    assert hushed._fused() is None

    from sitframe.plugins.frozen_evaluation import FrozenEvaluation
    from sitframe.runs.loop import _runs_out

    class Brief(FrozenEvaluation):  # (ends its runs early: each iteration must be asked)
        def terminated(self, context: Any) -> bool:
            return context.iteration >= 10

    assert _runs_out(None) and _runs_out(FrozenEvaluation())
    assert not _runs_out(Brief()) and not _runs_out(object())

    from sitframe.plugins.evolving import EvolvingInterpreter

    class Eager(EvolvingInterpreter):
        name = "eager"

    for cls in (EvolvingInterpreter, Eager):
        itp = cls(c=2, capacity=4)
        itp.load_state({"centers": np.ones((2, 8)), "feature_centers": np.ones((2, 8)),
                        "m": 2.0, "transform": "range", "offset": 0.1})
        assert (itp._fused() is None) == (cls is Eager)


def test_progress_counts_every_iteration_on_both_paths(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """``sitframe_progress`` adds up to each learning trial's iterations, compiled or not,
    wherever the trials run."""
    plugin, seen = tmp_path / "plugins", tmp_path / "seen.txt"
    plugin.mkdir()
    (plugin / "count.py").write_text(
        "from sitframe import hookimpl\n\n@hookimpl\n"
        "def sitframe_progress(trial, iterations):\n"
        f"    with open({str(seen)!r}, 'a') as f:\n"
        "        f.write(f'{trial} {iterations}\\n')\n")
    path = tmp_path / "p.toml"
    path.write_text(to_toml(_config({"experiment.iterations": 750, "experiment.trials": 2})))
    for mode in ("wait", "0"):
        monkeypatch.setenv("SITFRAME_FUSED", mode)
        seen.unlink(missing_ok=True)
        assert cli_main(["--plugins-dir", str(plugin), "run", str(path), "--out",
                         str(tmp_path / f"p{mode}.h5")]) == 0
        counts: dict[int, list[int]] = {}
        for line in seen.read_text().splitlines():
            trial, n = map(int, line.split())
            counts.setdefault(trial, []).append(n)
        assert counts == {0: [100] * 7 + [50], 1: [100] * 7 + [50]}


def test_a_learned_speed_over_a_fixed_heading_runs_compiled(tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    """The thesis's speed stage (the `speed` preset's shape): the heading rule base fixed
    from an earlier log, the speed learned with its own reward and learning-rate schedule,
    both outputs driving the robot; compiled and not, the same bits."""
    monkeypatch.setenv("SITFRAME_FUSED", "wait")
    base = tmp_path / "heading.toml"
    base.write_text(to_toml(_config({"experiment.iterations": 600})))
    heading_log = tmp_path / "heading.h5"
    assert cli_main(["run", str(base), "--out", str(heading_log)]) == 0
    cfg = _config({"experiment.stages": ["learn", "evaluate"],
                   "experiment.clusters_from": str(heading_log),
                   "behaviours.avoid.reward": "speed",
                   "behaviours.avoid.reward_params": {"near_time_s": 3.0},
                   "behaviours.avoid.speeds": [0.1, 0.2, 0.3],
                   "behaviours.avoid.learn": ["speed"],
                   "behaviours.avoid.alpha_visits": 20,
                   "behaviours.avoid.policy_from": {"log": str(heading_log), "trial": 0,
                                                    "behaviour": "avoid"}})
    del cfg["collect"]
    compiled, n_compiled = _run(tmp_path, "speed", cfg, monkeypatch, True)
    python, _n = _run(tmp_path, "speed", cfg, monkeypatch, False)
    assert n_compiled >= 1 and not _differ(compiled, python)
    assert any(k.endswith("speed/q_snapshots") for k in compiled)
    speed = next(np.asarray(v)[:, 1] for k, v in compiled.items()
                 if k.endswith("proposals/avoid"))  # (the blended speed each iteration)
    assert ((speed >= 0.1) & (speed <= 0.3)).all()


def test_snapshots_keep_only_the_rule_base_changes_of_a_call() -> None:
    """A call of the kernel writes its rule-base changes into buffers of a hundred rows; the
    learner keeps copies of the rows written, so a long trial's snapshots do not hold every
    call's whole buffer (a 100k-iteration trial of today's preset held 110 MiB so)."""
    from types import SimpleNamespace

    from sitframe.learning.fuzzy_q import RowStack

    c, a = 48, 7
    lr = SimpleNamespace(_snap_iter=[0], _snap_rules=RowStack(np.zeros(c, np.int64), np.int16),
                         _snap_greedy=RowStack(np.zeros(c, np.int64), np.int16),
                         _snap_q=RowStack(np.zeros((c, a))))
    state = fused._LearnerState.__new__(fused._LearnerState)
    state.lr = lr
    snaps = (np.arange(1, fused.EVERY + 1), np.ones((fused.EVERY, c), np.int64),
             np.ones((fused.EVERY, c), np.int64), np.ones((fused.EVERY, c, a)))
    for _ in range(20):  # (past the stacks' first buffers)
        state.snapshots(snaps, 2)
    snaps[3][:] = 5.0  # (the next call's changes overwrite the buffers)
    assert lr._snap_iter[:3] == [0, 1, 2] and len(lr._snap_q) == 41
    q = lr._snap_q.array()
    assert q.shape == (41, c, a) and (q[0] == 0.0).all() and (q[1:] == 1.0).all()
    assert lr._snap_rules.array().dtype == np.int16 and len(lr._snap_greedy) == 41


def test_a_row_stack_is_numpys_stack_of_its_rows() -> None:
    """The learner's snapshots: rows cast as ``astype`` casts, read back as ``numpy.stack``
    gives them, and a view handed out stays valid while rows are added."""
    from sitframe.learning.fuzzy_q import RowStack

    rng = np.random.default_rng(2)
    rows = [rng.integers(-40000, 40000, 5) for _ in range(100)]
    st = RowStack(rows[0], np.int16)
    for r in rows[1:40]:
        st.append(r)
    early = st.array()
    st.extend(np.array(rows[40:]))
    assert np.array_equal(st.array(), np.stack(rows).astype(np.int16))
    assert np.array_equal(early, np.stack(rows[:40]).astype(np.int16))


def test_a_compiled_trial_refuses_bad_td_errors_as_the_python_loop_does(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A Q table that overflows gives TD errors of NaN; the tracker refuses them, naming the
    behaviour and its ``situation_errors``, whichever path the trial runs (the compiled one
    checks them before it sums them)."""
    cfg = _config({**EVOLVING, "experiment.iterations": 600, "behaviours.avoid.q_init": "random",
                   "behaviours.avoid.q_init_value": 1e308, "behaviours.avoid.q_init_spread": 1e308})
    path = tmp_path / "nan.toml"
    path.write_text(to_toml(cfg))
    said, calls = {}, []
    real = fused.run
    monkeypatch.setattr(fused, "run", lambda *a, **k: calls.append(1) or real(*a, **k))
    for mode in ("wait", "0"):
        monkeypatch.setenv("SITFRAME_FUSED", mode)
        assert cli_main(["run", str(path), "--out", str(tmp_path / f"{mode}.h5"),
                         "--workers", "1"]) != 0
        said[mode] = [ln for ln in capsys.readouterr().err.splitlines() if "error:" in ln]
    assert calls == [1]  # (the compiled trial ran, and failed)
    assert said["wait"] == said["0"] and len(said["0"]) == 1
    assert "situation_errors()" in said["0"][0] and "TD error of nan" in said["0"][0]
