"""The Gymnasium environments (sitframe.gym) and the frozen SB3 policy behaviour."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra (gymnasium) is not installed")

from gymnasium.utils.env_checker import check_env  # noqa: E402

import sitframe.gym as sg  # noqa: E402
from sitframe.errors import InputError  # noqa: E402


@pytest.fixture(scope="module")
def oa_task() -> sg.Task:
    return sg.Task.from_config("obstacle-avoidance", max_steps=15)


@pytest.mark.parametrize("env_id", list(sg.ENV_IDS))
def test_registered_envs_pass_check_env(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array" if env_id.endswith("Following-v0") else None)
    check_env(env.unwrapped, skip_render_check=not env_id.endswith("Following-v0"))
    obs, _ = env.reset(seed=3)
    assert env.observation_space.contains(obs)


def test_spaces_follow_the_config() -> None:
    oa = gym.make("sitframe/ObstacleAvoidance-v0").unwrapped
    assert oa.observation_space.shape == (8,) and oa.action_space.n == 7
    goal = gym.make("sitframe/GoalFinding-v0").unwrapped
    assert goal.observation_space.shape == (10,)  # 8 beams + goal distance, bearing
    assert goal.reward_fn.name == "goal-progress"  # the preset learns nothing
    raw = sg.make_env("wall-following", normalize=False, continuous=True)
    assert raw.action_space.shape == (1,) and raw.observation_space.high[0] == 3.0
    obs, _ = raw.reset(seed=0)
    assert obs.max() > 1.0  # metres, not normalised


def test_same_seed_same_episode(oa_task: sg.Task) -> None:
    def episode(seed: int) -> list[tuple]:
        env = sg.SitframeEnv(task=oa_task)
        obs, info = env.reset(seed=seed)
        out = [(obs.tobytes(), info["pose"].tobytes())]
        for a in [0, 3, 6, 3, 1] * 4:
            obs, r, te, tr, info = env.step(a)
            out.append((obs.tobytes(), r, te, tr, info["pose"].tobytes()))
        return out

    assert episode(5) == episode(5)
    assert episode(5)[0] != episode(6)[0]  # another random start


def test_time_limit_truncates_and_collision_can_terminate(oa_task: sg.Task) -> None:
    env = sg.SitframeEnv(task=oa_task)
    env.reset(seed=0)
    flags = [env.step(3)[2:4] for _ in range(15)]
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])
    crash = sg.make_env("obstacle-avoidance", terminate_on_collision=True)
    world = crash.world
    x0, y0, _x1, _y1 = world.bounds
    crash.reset(seed=0, options={"pose": (x0 + 0.25, y0 + 2.0, np.pi)})  # facing the wall
    _o, r, term, trunc, info = crash.step(3)
    assert info["collided"] and term and not trunc and r == -30.0


def test_goal_reached_terminates() -> None:
    env = sg.make_env("goal-finding")
    env.reset(seed=0)
    p = env.pose
    goal = (p[0] + 0.3 * np.cos(p[2]), p[1] + 0.3 * np.sin(p[2]), 0.3)
    env.reset(seed=0, options={"goal": goal})
    obs, r, term, trunc, _info = env.step(3)  # straight ahead: 0.225 m, inside the goal disc
    assert term and not trunc and r == env.reward_fn.goal  # the arrival bonus
    assert obs[-1] == pytest.approx(0.0, abs=1e-3)  # bearing: dead ahead


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize(("config", "continuous"), [("obstacle-avoidance", False),
                                                    ("goal-finding", True)])
def test_vector_env_equals_single_envs(config: str, continuous: bool, compiled: bool,
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    from sitframe.sim import kernels

    if compiled and kernels.load() is None:
        pytest.skip("compiled kernels switched off or numba missing")
    monkeypatch.setattr(kernels, "_LOADED", [kernels.load() if compiled else None])
    n, seed = 3, 11
    venv = sg.SitframeVectorEnv(config, num_envs=n, max_steps=15, continuous=continuous)
    singles = [sg.SitframeEnv(task=venv.task, continuous=continuous) for _ in range(n)]
    vobs, _ = venv.reset(seed=seed)
    sobs = [e.reset(seed=seed + i)[0] for i, e in enumerate(singles)]
    np.testing.assert_array_equal(vobs, np.stack(sobs))
    rng = np.random.default_rng(0)  # 40 steps: past one autoreset each
    acts = rng.uniform(-1, 1, (40, n, 1)) if continuous else rng.integers(0, 7, (40, n))
    done = [False] * n
    for a in acts:
        vobs, vr, vte, vtr, vinfo = venv.step(a)
        for i, e in enumerate(singles):
            if done[i]:  # NEXT_STEP autoreset: this step only resets
                o, r, te, tr = e.reset()[0], 0.0, False, False
            else:
                o, r, te, tr, _ = e.step(a[i])
            np.testing.assert_array_equal(vobs[i], o)
            assert (vr[i], vte[i], vtr[i]) == (r, te, tr)
            np.testing.assert_array_equal(vinfo["pose"][i], e.pose)
            done[i] = te or tr
        for mine, e in zip(venv.envs, singles, strict=True):  # (the robots' own envs, whose
            np.testing.assert_array_equal(mine.pose, e.pose)  # state the compiled step keeps
            np.testing.assert_array_equal(mine._reading, e._reading)  # apart, brought up to
            assert mine.t == e.t  # date)
    assert venv.observation_space.shape == (n, 10 if config == "goal-finding" else 8)


def test_vector_env_steps_a_dead_ahead_contact_as_its_single_env() -> None:
    """A robot driving square into a wall (its turn after the contact a draw from its own
    generator, stepped apart from the compiled batch) beside robots that touch at an angle or
    stay free: each as its single env, step after step."""
    from sitframe.sim import kernels

    if kernels.load() is None or kernels.contact() is None:
        pytest.skip("the compiled step is not used here")
    n, opts = 4, {"pose": [12.75, 4.0, 0.0]}  # 0.1 m from the training room's east wall
    venv = sg.SitframeVectorEnv("obstacle-avoidance", num_envs=n, max_steps=30)
    singles = [sg.SitframeEnv(task=venv.task) for _ in range(n)]
    venv.reset(seed=3, options=opts)
    for i, e in enumerate(singles):
        e.reset(seed=3 + i, options=opts)
    acts = [[3, 1, 6, 3]] + np.random.default_rng(1).integers(0, 7, (12, n)).tolist()
    for a in np.array(acts):
        vobs, vr, vte, vtr, vinfo = venv.step(a)
        for i, e in enumerate(singles):
            o, r, te, tr, info = e.step(int(a[i]))
            np.testing.assert_array_equal(vobs[i], o)
            assert (vr[i], vte[i], vtr[i], vinfo["collided"][i]) == (r, te, tr,
                                                                     info["collided"])
            np.testing.assert_array_equal(vinfo["pose"][i], e.pose)
    assert venv._fast  # (the compiled batch ran)


def test_sonar_read_many_equals_read() -> None:
    from sitframe.plugins.sonar import SonarRing
    from sitframe.sim.world import load_world

    world = load_world("training")
    rng = np.random.default_rng(1)
    poses = np.stack([world.random_free_pose(rng) for _ in range(5)])
    for kw in ({"beam_width_deg": 25, "rays_per_beam": 5}, {"noise_std": 0.02, "dropout": 0.2}):
        ring = SonarRing(**kw)
        many = ring.read_many(world, poses, [np.random.default_rng(i) for i in range(5)])
        one = [ring.read(world, p, np.random.default_rng(i)) for i, p in enumerate(poses)]
        np.testing.assert_array_equal(many, np.stack(one))


def test_bad_arguments_are_one_clear_error() -> None:
    with pytest.raises(InputError, match="unknown experiment 'nope'"):
        sg.make_env("nope")
    with pytest.raises(ValueError, match="max_steps"):
        sg.make_env("obstacle-avoidance", max_steps=0)
    with pytest.raises(InputError, match="reward"):
        sg.make_env("obstacle-avoidance", reward="no-such-reward")
    env = sg.make_env("obstacle-avoidance")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action 9 out of range"):
        env.step(9)


def _sb3_table(model: str) -> dict:
    return {"component": "sb3-policy", "model": model, "algorithm": "dqn"}


def test_sb3_behaviour_without_sb3_names_the_extra(tmp_path, monkeypatch) -> None:
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager

    model = tmp_path / "m.zip"
    model.write_bytes(b"")
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # import fails
    reg = Registry.collect(get_plugin_manager())
    with pytest.raises(InputError) as err:
        reg.create("behaviour", "sb3-policy", {"model": str(model)}, file="c.toml",
                   key="behaviours.avoid")
    msg = str(err.value)
    assert "sitframe[baselines]" in msg and "sb3-policy" in msg and "\n" not in msg


@pytest.fixture(scope="module")
def sb3_model(tmp_path_factory) -> tuple:
    """``(model, path)``: a DQN smoke-trained 300 steps on the obstacle-avoidance env, saved."""
    sb3 = pytest.importorskip("stable_baselines3", reason="the baselines extra is not installed")
    import torch

    torch.set_num_threads(1)
    model = sb3.DQN("MlpPolicy", sg.make_env("obstacle-avoidance"), learning_starts=100, seed=0,
                    device="cpu", policy_kwargs={"net_arch": [16]})
    model.learn(300)  # a smoke run: the policy need not be good
    path = tmp_path_factory.mktemp("sb3") / "avoid.zip"
    model.save(path)
    return model, path


def test_sb3_policy_behaviour_acts_as_in_the_env(sb3_model) -> None:
    from sitframe.contract.config import load_config
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager
    from sitframe.contract.records import Context
    from sitframe.contract.resolve import Resolved

    model, path = sb3_model
    env = sg.make_env("obstacle-avoidance")
    # CDB fuses it with goal finding: the goal-finding preset with this behaviour as 'avoid'
    cfg, _s, _b = load_config("goal-finding")
    cfg["behaviours"]["avoid"] = _sb3_table(str(path))
    res = Resolved.build(cfg, Registry.collect(get_plugin_manager()), "test")
    beh = res.behaviours()["avoid"][0]
    obs, _ = env.reset(seed=2)
    for a in (0, 3, 5):
        act, _ = model.predict(obs, deterministic=True)
        ctx = Context(0, env.pose, env._reading, np.ones(12) / 12, float(env._reading.min()),
                      env.world, None)
        assert beh.propose(ctx).heading_deg == env.task.headings[int(act)]
        obs, *_ = env.step(a)


def test_evaluate_rescores_an_sb3_run_with_its_own_model(sb3_model, tmp_path, capsys) -> None:
    import shutil

    from helpers import run_config, run_json, small_config

    from sitframe.cli.app import main

    model = tmp_path / "avoid.zip"
    shutil.copy(sb3_model[1], model)
    cfg = small_config(name="sb3", trials=1, iterations=60, c=4, fcm_trials=2,
                       eval_iterations=60).replace(
        'component = "fuzzy-q"\nreward = "obstacle-avoidance"\np = 5',
        f'component = "sb3-policy"\nmodel = "{model.as_posix()}"\nalgorithm = "dqn"')
    _cfg, log = run_config(tmp_path, cfg, "sb3.h5")
    run = json.loads(capsys.readouterr().out)["trials"][0]["evaluation"]
    got = run_json(capsys, "evaluate", str(log), "--world", "novel-1", "--iterations", "60",
                   "--json")
    # the frozen evaluation of the run, re-scored from the log: the same policy, the same numbers
    assert {f"novel-1/{k}": got[k] for k in ("collisions", "distance_m", "coverage")} == \
        {k: run[k] for k in ("novel-1/collisions", "novel-1/distance_m", "novel-1/coverage")}
    fused = run_json(capsys, "evaluate", str(log), "--world", "novel-1", "--goal-episodes", "2",
                     "--json")
    assert fused["episodes"] == 2 and fused["arbiter"] == "cdb"  # CDB with goal finding
    model.write_bytes(model.read_bytes() + b"x")  # another model under the run's file name
    for broken in ("has changed since the run", "file not found"):
        assert main(["evaluate", str(log), "--world", "novel-1", "--json"]) == 2
        err = capsys.readouterr().err
        assert broken in err and "sb3.h5" in err and err.count("\n") == 1
        model.unlink(missing_ok=True)  # then: no model at all


@pytest.mark.parametrize("worlds", [None, ["gen:1000000", "gen:1000001", "novel-1"]])
def test_compiled_step_equals_the_python_step(worlds: list[str] | None,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """``SitframeEnv.step`` in one compiled call (``CompiledStep``) gives what ``step_robot``,
    the sonar and the observation give, collisions and resets included."""
    from sitframe.gym import env as genv
    from sitframe.sim import kernels

    if kernels.load() is None or kernels.contact() is None:
        pytest.skip("the compiled step is not used here")
    kw = {} if worlds is None else {"worlds": worlds}
    fast = sg.SitframeEnv("obstacle-avoidance", max_steps=60, **kw)
    slow = sg.SitframeEnv(task=fast.task)
    monkeypatch.setattr(slow, "_compile", lambda: None)
    acts = np.random.default_rng(4).integers(0, fast.action_space.n, 400)
    for e in (fast, slow):
        e.reset(seed=9)
    hits = 0
    for a in acts:
        got, want = fast.step(int(a)), slow.step(int(a))
        np.testing.assert_array_equal(got[0], want[0])
        assert got[1:4] == want[1:4]
        assert got[4].keys() == want[4].keys() and all(
            np.array_equal(got[4][k], want[4][k]) for k in got[4])
        hits += got[4]["collided"]
        if got[2] or got[3]:
            np.testing.assert_array_equal(fast.reset()[0], slow.reset()[0])
    assert isinstance(fast._compiled, genv.CompiledStep) and hits > 10
