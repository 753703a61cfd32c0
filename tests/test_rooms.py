"""Learning over a family of rooms (``experiment.rooms``), collection in rooms without
trajectories, and the reward against circling (issue 39)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from helpers import run_config, small_config

from sitframe.cli.app import main
from sitframe.contract.config import load_config
from sitframe.errors import InputError
from sitframe.logs.compare import compare_logs
from sitframe.logs.reader import open_log
from sitframe.sim.world import load_world

ROOMS = ("training", "novel-1", "novel-2")


def rooms_config(*, rooms: tuple[str, ...] = ROOMS, episode: int = 60, trials: int = 2,
                 name: str = "rooms") -> str:
    """A small run whose trials learn over ``rooms`` in ``episode``-iteration episodes."""
    listed = ", ".join(f'"{r}"' for r in rooms)
    return small_config(name=name, trials=trials, iterations=300).replace(
        "seed = 3", f"seed = 3\nrooms = [{listed}]\nepisode_iterations = {episode}")


@pytest.fixture(scope="module")
def rooms_log(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rooms")
    return run_config(folder, rooms_config(), "rooms.h5", "--workers", "1")


def test_a_trial_over_rooms_records_the_room_of_every_iteration(rooms_log):
    _cfg, out = rooms_log
    tl = open_log(out).trial(1)
    first = tl.episodes["learn/first_iteration"]
    room = tl.arrays["room"]
    assert first.tolist() == [0, 60, 120, 180, 240]
    assert room.shape == (300,)
    # each episode runs in one room; the rooms come in shuffled rounds, each room once
    per_episode = tl.episodes["learn/room"]
    assert room.tolist() == np.repeat(per_episode, 60).tolist()
    assert sorted(per_episode[:3].tolist()) == [0, 1, 2]
    with h5py.File(out) as f:
        assert f["trials/0001/episodes/learn"].attrs["rooms"] == '["training", "novel-1", ' \
                                                                  '"novel-2"]'
    # every pose lies inside the room the log names for it, and episodes start afresh
    pose = tl.arrays["pose"]
    worlds = [load_world(r) for r in ROOMS]
    for i, w in enumerate(worlds):
        assert w.inside(pose[:-1][room == i, :2]).all()
    starts = pose[first]
    assert len({tuple(np.round(s, 6)) for s in starts}) == len(first)
    assert int(tl.summary["rooms_visited"]) == 3
    assert 0.0 < float(tl.summary["coverage"]) <= 1.0


def test_learning_over_rooms_is_deterministic_and_resumes(rooms_log, tmp_path):
    cfg, out = rooms_log
    again = tmp_path / "again.h5"
    assert main(["run", str(cfg), "--out", str(again), "--workers", "2"]) == 0
    assert compare_logs(out, again) == []
    with h5py.File(again, "a") as f:  # an interrupted run: trial 1 missing
        f.attrs["status"] = "aborted"
        del f["trials/0001"]
    assert main(["run", "--resume", str(again)]) == 0
    assert compare_logs(out, again) == []


def test_other_seeds_draw_other_rooms_and_starts(tmp_path):
    _c, a = run_config(tmp_path, rooms_config(trials=1), "a.h5", "--workers", "1")
    _c, b = run_config(tmp_path, rooms_config(trials=1, name="b"), "b.h5", "--workers", "1",
                       "--seed", "4")
    pa, pb = (open_log(p).trial(0).arrays["pose"] for p in (a, b))
    assert not np.array_equal(pa, pb)


@pytest.mark.parametrize(("edit", "key", "says"), [
    (lambda t: t.replace('rooms = ["training", "novel-1", "novel-2"]', "rooms = []"),
     "experiment.rooms", "non-empty list"),
    (lambda t: t.replace('"novel-1", "novel-2"]', '"no-such-room"]'),
     "experiment.rooms[1]", "no-such-room"),
    (lambda t: t.replace("episode_iterations = 60", "episode_iterations = 0"),
     "experiment.episode_iterations", "integer"),
    (lambda t: t.replace('rooms = ["training", "novel-1", "novel-2"]\n', ""),
     "experiment.episode_iterations", "experiment.rooms"),
    (lambda t: t.replace("episode_iterations = 60", "episode_iterations = 60\n"
                         "tight_starts = 1.5"), "experiment.tight_starts", "[0.0, 1.0]"),
    (lambda t: t.replace('rooms = ["training", "novel-1", "novel-2"]\nepisode_iterations = 60',
                         "tight_starts = 0.5"), "experiment.tight_starts", "experiment.rooms"),
], ids=["empty", "unknown-room", "zero-episode", "episode-without-rooms", "tight-above-1",
        "tight-without-rooms"])
def test_a_bad_rooms_key_is_one_line_naming_it(tmp_path, capsys, edit, key, says):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(edit(rooms_config()))
    assert main(["run", str(cfg), "--out", str(tmp_path / "bad.h5")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith("sitframe: error:") and f"{cfg}: {key}:" in err and says in err, err
    assert not (tmp_path / "bad.h5").exists()


def test_tight_starts_begin_episodes_nearer_the_walls():
    """``tight_starts = 1``: every episode starts at the free pose nearest a wall of those
    drawn, so much nearer the walls than uniform starts, the same for the same seed; 0 draws
    exactly what a config without the key draws."""
    from sitframe.runs.loop import RoomEpisodes
    from sitframe.sim.robot import RobotParams

    worlds = [load_world(r) for r in ROOMS]

    def starts(tight: float, seed: int = 7) -> np.ndarray:
        eps = RoomEpisodes(worlds, 50, seed, RobotParams(), tight)
        got = [next(eps.pairs) for _ in range(30)]
        return np.array([w.clearance(p[None, :2])[0] for p, _g, w in got]), \
            np.array([p for p, _g, _w in got])

    (near, pn), (uniform, pu) = starts(1.0), starts(0.0)
    assert np.median(near) < 0.5 * np.median(uniform), (np.median(near), np.median(uniform))
    assert np.array_equal(pn, starts(1.0)[1])
    legacy = RoomEpisodes(worlds, 50, 7, RobotParams())
    assert np.array_equal(pu, np.array([next(legacy.pairs)[0] for _ in range(30)]))
    assert (near >= RobotParams().radius + RoomEpisodes.MARGIN).all()


def test_a_config_without_rooms_keeps_its_text():
    """Presets that do not use rooms keep their config (and so their log) bit for bit."""
    cfg, _s, _b = load_config("obstacle-avoidance-thesis")
    assert "rooms" not in cfg["experiment"] and "episode_iterations" not in cfg["experiment"]


def test_both_modes_collect_in_rooms_without_trajectories(tmp_path, capsys):
    text = small_config(trials=1, iterations=50).replace(
        'worlds = ["collect-1", "collect-2"]',
        'mode = "both"\nwander_samples = 30\nworlds = ["collect-1", "training"]')
    _c, out = run_config(tmp_path, text, "both.h5", "--workers", "1")
    collected = open_log(out).stage("collect")
    counts = np.bincount(collected["source"], minlength=2)
    assert counts[1] == 30 and counts[0] > 30  # training: wandered only; collect-1: both
    bad = tmp_path / "traj.toml"
    bad.write_text(text.replace('mode = "both"', 'mode = "trajectory"'))
    capsys.readouterr()
    assert main(["run", str(bad), "--out", str(tmp_path / "traj.h5")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "collect.worlds[1]" in err and "'training'" in err


def test_progress_reward_pays_for_distance_not_for_circling():
    from types import SimpleNamespace as NS

    from plugins.rewards import ObstacleAvoidanceReward

    def tr(a, b, heading=0.0):
        return NS(before=NS(pose=np.array([*a, 0.0])), after=NS(pose=np.array([*b, 0.0])),
                  outcome=NS(collided=False), command=NS(heading_change_deg=heading))

    plain = ObstacleAvoidanceReward()
    assert plain(tr((0, 0), (1, 0), 30.0)) == pytest.approx(27.0)
    r = ObstacleAvoidanceReward(progress=5.0, progress_window=2)
    line = [r(tr((x, 0), (x + 0.2, 0))) for x in (0.0, 0.2, 0.4, 0.6)]
    assert line == pytest.approx([31.0] * 4)  # each step 0.2 m farther from 2 steps back
    assert r(tr((0.8, 0), (0.6, 0))) == pytest.approx(29.0)  # turning back costs
    # a jump (a new episode) starts the window again
    assert r(tr((5, 5), (5.2, 5))) == pytest.approx(31.0)
    c = ObstacleAvoidanceReward(progress=5.0, progress_window=2)
    ring = [(0.2 * np.cos(a), 0.2 * np.sin(a)) for a in np.linspace(0, 4 * np.pi, 13)]
    paid = [c(tr(ring[i], ring[i + 1])) - 30.0 for i in range(12)]
    # circling (a step of the same length, turning 60 deg) earns under a third of a line
    assert max(paid[2:]) < (line[-1] - 30.0) / 3
    with pytest.raises(InputError, match="progress_window"):
        ObstacleAvoidanceReward(progress_window=0)


def candidates_config(name: str = "cands") -> str:
    return rooms_config(trials=1, name=name).replace(
        "episode_iterations = 60", "episode_iterations = 60\ncandidates = 3\n"
        'validation_rooms = ["novel-1", "collect-2"]\nvalidation_iterations = 80')


def test_candidates_keep_the_rule_base_best_in_the_validation_rooms(tmp_path):
    _c, out = run_config(tmp_path, candidates_config(), "cands.h5", "--workers", "1")
    tl = open_log(out).trial(0)
    sel = {k[len("select/"):]: v for k, v in tl.episodes.items() if k.startswith("select/")}
    assert sel["first_iteration"].tolist() == [0, 100, 200]
    score = sel["collisions_per_1000"] - 20.0 * sel["coverage"]
    assert np.allclose(sel["score"], score)
    best = int(tl.summary["candidate"])
    assert best == int(np.argmin(score))
    assert int(tl.summary["validation_iterations"]) == 3 * 2 * 80
    # the logged (and evaluated) policy is the kept candidate's: it scores as recorded
    from sitframe.runs.evaluation import evaluate_log

    runs = [evaluate_log(str(out), world=w, trial=0, iterations=80) for w in
            ("novel-1", "collect-2")]
    assert all(r["iterations"] == 80 for r in runs)
    again = tmp_path / "again.h5"
    assert main(["run", str(tmp_path / "cands.toml"), "--out", str(again), "--workers",
                 "1"]) == 0
    assert compare_logs(out, again) == []


@pytest.mark.parametrize(("edit", "key"), [
    (lambda t: t.replace('validation_rooms = ["novel-1", "collect-2"]\n', ""),
     "experiment.candidates"),
    (lambda t: t.replace("candidates = 3\n", ""), "experiment.validation_iterations"),
    (lambda t: t.replace('"novel-1", "collect-2"]', '"novel-1", "nowhere"]'),
     "experiment.validation_rooms[1]"),
    (lambda t: t.replace("candidates = 3", "candidates = 301"), "experiment.candidates"),
    (lambda t: t.replace('component = "fcm"', 'component = "evolving"'),
     "experiment.candidates"),
], ids=["no-rooms", "no-candidates", "unknown-room", "too-many", "evolving"])
def test_a_bad_candidates_key_is_one_line_naming_it(tmp_path, capsys, edit, key):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(edit(candidates_config()))
    assert main(["run", str(cfg), "--out", str(tmp_path / "bad.h5")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{cfg}: {key}:" in err, err


def test_the_learning_path_figure_is_drawn_in_the_room_the_robot_was_in():
    from types import SimpleNamespace as NS

    from sitframe.analysis.report import _room_at

    tr = NS(world="training", arrays={"room": np.repeat([2, 0, 0, 1], 50)},
            episodes={"learn/rooms": '["training", "novel-1", "novel-2"]'})
    assert _room_at(tr, 10, 110) == ("novel-2", 50)  # up to where it left novel-2
    assert _room_at(tr, 60, 160) == ("training", 150)
    assert _room_at(NS(world="training", arrays={}, episodes={}), 0, 100) == ("training", 100)
