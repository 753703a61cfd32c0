"""Gymnasium envs over several worlds: each reset draws the episode's world from ``np_random``."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("gymnasium", reason="the gym extra (gymnasium) is not installed")

import sitframe.gym as sg  # noqa: E402

WORLDS = ["training", "novel-1", "novel-2"]


@pytest.fixture(scope="module")
def task() -> sg.Task:
    return sg.Task.from_config("obstacle-avoidance", worlds=WORLDS, max_steps=12)


def test_each_reset_draws_a_world_deterministically(task: sg.Task) -> None:
    env = sg.SitframeEnv(task=task)
    drawn = []
    for seed in range(30):
        _obs, info = env.reset(seed=seed)
        assert env.world.is_free(info["pose"][None, :2], task.res.robot.radius)[0]
        drawn.append(info["world"])
    assert set(drawn) == set(WORLDS)  # every world is drawn, by the env's own generator
    again = sg.SitframeEnv(task=task)
    assert [again.reset(seed=s)[1]["world"] for s in range(30)] == drawn
    # unseeded resets go on drawing from the same generator: a seeded sequence repeats
    env.reset(seed=7)
    seq = [env.reset()[1]["world"] for _ in range(10)]
    env.reset(seed=7)
    assert [env.reset()[1]["world"] for _ in range(10)] == seq
    assert len(set(seq)) > 1


def test_world_option_and_bad_arguments(task: sg.Task) -> None:
    env = sg.SitframeEnv(task=task)
    _obs, info = env.reset(seed=0, options={"world": "novel-2"})
    assert info["world"] == "novel-2" and env.world.name == "novel-2"
    with pytest.raises(ValueError, match="one of the env's worlds"):
        env.reset(seed=0, options={"world": "office"})
    with pytest.raises(ValueError, match="not both"):
        sg.make_env("obstacle-avoidance", world="training", worlds=WORLDS)
    with pytest.raises(ValueError, match="non-empty list"):
        sg.make_env("obstacle-avoidance", worlds="training")


def test_one_world_draws_nothing() -> None:
    """A one-world env's episodes are those of an env made without ``worlds``."""
    a = sg.make_env("obstacle-avoidance", worlds=["novel-1"], max_steps=5)
    b = sg.make_env("obstacle-avoidance", world="novel-1", max_steps=5)
    for s in range(3):
        np.testing.assert_array_equal(a.reset(seed=s)[0], b.reset(seed=s)[0])
        np.testing.assert_array_equal(a.step(2)[0], b.step(2)[0])


def test_vector_env_over_worlds_equals_single_envs(task: sg.Task) -> None:
    n, seed = 4, 3
    venv = sg.SitframeVectorEnv("obstacle-avoidance", num_envs=n, worlds=WORLDS, max_steps=12)
    singles = [sg.SitframeEnv(task=venv.task) for _ in range(n)]
    vobs, _ = venv.reset(seed=seed)
    sobs = [e.reset(seed=seed + i)[0] for i, e in enumerate(singles)]
    np.testing.assert_array_equal(vobs, np.stack(sobs))
    rng = np.random.default_rng(0)
    done, seen = [False] * n, set()
    for a in rng.integers(0, 7, (40, n)):  # past three autoresets each: new worlds drawn
        vobs, vr, vte, vtr, vinfo = venv.step(a)
        for i, e in enumerate(singles):
            if done[i]:
                o, r, te, tr = e.reset()[0], 0.0, False, False
            else:
                o, r, te, tr, _ = e.step(a[i])
            np.testing.assert_array_equal(vobs[i], o)
            assert (vr[i], vte[i], vtr[i]) == (r, te, tr)
            np.testing.assert_array_equal(vinfo["pose"][i], e.pose)
            assert venv.envs[i].world is e.world or venv.envs[i].world.name == e.world.name
            seen.add(e.world.name)
            done[i] = te or tr
    assert len(seen) > 1  # the robots really were in different worlds
