"""Situation spaces per behaviour: [spaces.NAME] tables, logged, analysed, evaluated."""

from __future__ import annotations

import json
import sys
import textwrap

import numpy as np
import pytest
from helpers import run_config, run_json

from sitframe.analysis import results as R
from sitframe.cli.app import main
from sitframe.logs.reader import open_log

#: Avoidance over the default 6 situations, wall following over 4 situations of its own
#: that see only the four side beams (its own data: wander readings of another room).
TWO_SPACES = """
[experiment]
name = "two-spaces"
trials = 2
iterations = 300
seed = 4

[collect]
worlds = ["collect-1", "collect-2"]

[interpreter]
component = "fcm"
c = 6
trials = 3

[spaces.wall]
component = "fcm"
c = 4
trials = 3
transform = "inverse"
view = [0, 1, 6, 7]
collect = { mode = "wander", worlds = ["wall-following"], wander_samples = 200 }

[behaviours.avoid]
component = "fuzzy-q"
reward = "obstacle-avoidance"
p = 5

[behaviours.follow]
component = "fuzzy-q"
reward = "wall-following"
headings = [90, 40, 0, -40, -90]
space = "wall"
p = 5

[arbiter]
component = "cdb"

[evaluate]
worlds = ["novel-1"]
iterations = 100
"""


@pytest.fixture(scope="module")
def two(tmp_path_factory):
    folder = tmp_path_factory.mktemp("spaces")
    _cfg, log = run_config(folder, TWO_SPACES, "two.h5")
    return log


def test_a_run_with_two_spaces_logs_both(two):
    lg = open_log(two)
    assert lg.space_names() == ["wall"]
    sp = lg.space("wall")
    assert sp["readers"] == ["follow"] and sp["source"] == "fitted"
    assert sp["view"].tolist() == [0, 1, 6, 7]
    assert np.asarray(sp["state"]["centers"]).shape == (4, 4)  # 4 situations over 4 readings
    assert len(sp["labels"]) == 4 and sp["labels"][0].startswith("S1: ")
    assert np.asarray(sp["samples"]).shape[1] == 4  # its own data, seen through its view
    tr = lg.trial(1)
    assert tr.arrays["memberships"].shape[1] == 6
    u = tr.arrays["spaces/wall/memberships"]
    assert u.shape == (300, 4) and np.allclose(u.sum(axis=1), 1.0)
    # each behaviour's policy has one rule per situation of its own space
    assert tr.policies["avoid"].outputs["heading"].rules.size == 6
    assert tr.policies["follow"].outputs["heading"].rules.size == 4
    assert tr.behaviours["follow"]["space"] == "wall" and tr.behaviours["avoid"]["space"] \
        == "default"
    # the evaluation logs both spaces' memberships too
    assert tr.episodes["eval/novel-1/spaces/wall/memberships"].shape == (100, 4)


def test_the_memberships_are_the_space_interpreters(two):
    """What follow read is its own interpreter's memberships of the readings in its view."""
    from sitframe.contract.config import validate_config
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager
    from sitframe.contract.resolve import Resolved

    lg = open_log(two)
    res = Resolved.build(validate_config(lg.config), Registry.collect(get_plugin_manager()))
    interp = res.space_interpreter("wall")
    interp.load_state(lg.space("wall")["state"])
    tr = lg.trial(0)
    for t in (0, 150, 299):
        want = interp.memberships(tr.arrays["reading"][t][[0, 1, 6, 7]])
        assert np.array_equal(want, tr.arrays["spaces/wall/memberships"][t])


def test_analysis_reads_both_spaces(two, tmp_path):
    table = R.spaces_table(two)
    assert table.column("Space") == ["default", "wall"]
    assert table.column("Situations") == [6, 4]
    assert table.column("Read by") == ["avoid, arbiter", "follow"] or \
        table.column("Read by")[1] == "follow"
    assert table.column("Readings [deg]")[1] == "+90 +50 -50 -90"
    assert len(R.situation_labels(two, space="wall")) == 4
    rb = R.rule_bases_across_trials(two, "follow")
    assert len(rb.rows) == 4  # the follow rule base over its own 4 situations
    assert len(R.rule_base_table(two, 0, "follow").rows) == 4
    assert R.exploration_counts(open_log(two).trial(0), "follow").shape == (4, 5)
    from sitframe.analysis import analyse

    rep = analyse(two, tmp_path / "an")
    names = {f for _s, f, _c in rep.files}
    assert {"spaces.md", "prototypes_wall.png", "rule_bases_follow.md"} <= names


def test_evaluate_shows_each_space(two, capsys):
    doc = run_json(capsys, "evaluate", str(two), "--world", "novel-2", "--trial", "1",
                   "--iterations", "50", "--json")
    assert doc["spaces"]["wall"] == {"situations": 4, "view": [0, 1, 6, 7],
                                     "read_by": ["follow"]}
    assert doc["spaces"]["default"]["situations"] == 6
    assert main(["evaluate", str(two), "--world", "novel-2", "--iterations", "20"]) == 0
    out = capsys.readouterr().out
    assert "space wall: 4 situations over readings [0, 1, 6, 7], read by follow" in out


def test_a_space_reused_from_a_log_by_clusters_from(two, tmp_path, capsys):
    """A space's clusters_from takes another log's fitted [interpreter] situations."""
    cfg = TWO_SPACES.replace('collect = { mode = "wander", worlds = ["wall-following"], '
                             'wander_samples = 200 }', f'clusters_from = "{two}"')
    cfg = cfg.replace("c = 4\ntrials = 3\ntransform = \"inverse\"\nview = [0, 1, 6, 7]",
                      "c = 6\ntrials = 3")
    _c, log = run_config(tmp_path, cfg.replace("iterations = 300", "iterations = 60"), "r.h5")
    lg = open_log(log)
    assert lg.space("wall")["source"] == f"clusters_from: {two}"
    assert np.array_equal(lg.space("wall")["state"]["centers"],
                          open_log(two).interpreter_state()["centers"])
    assert "spaces/wall" in json.loads(lg.attrs["inputs"])  # fingerprinted as an input


THIRD_PARTY = """
import numpy as np
from sitframe import LearnedPolicy, PolicyOutput, Proposal, hookimpl

SEEN = []

class Tally:
    '''A behaviour that knows nothing of spaces: it proposes from its memberships.'''
    name = "tally"
    def bind(self, run):
        SEEN.append(("bind", run.space, run.n_situations))
    def reset(self, rng, n_situations, iterations):
        SEEN.append(("reset", n_situations))
        self.c = n_situations
    def propose(self, context):
        SEEN.append(("u", context.memberships.shape[0], sorted(context.spaces or {})))
        return Proposal(float(10 * np.argmax(context.memberships)), None)
    def learn(self, transition, reward):
        SEEN.append(("learn", transition.before.memberships.shape[0]))
    def policy(self):
        return LearnedPolicy({"turn": PolicyOutput(np.arange(3.0), np.zeros(self.c, np.int16))})
    def load_policy(self, policy):
        SEEN.append(("load", policy.outputs["turn"].rules.size))

@hookimpl
def sitframe_behaviours():
    return [Tally]
"""


def test_a_third_party_behaviour_gets_its_own_space_from_config_alone(tmp_path, monkeypatch):
    """A plugin package (installed as pip would, entry point) with no code about spaces."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "tally_plugin.py").write_text(textwrap.dedent(THIRD_PARTY))
    dist = site / "tally_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: tally-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[sitframe]\ntally = tally_plugin\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.delitem(sys.modules, "tally_plugin", raising=False)
    cfg = TWO_SPACES.replace('[behaviours.follow]\ncomponent = "fuzzy-q"\n'
                             'reward = "wall-following"\nheadings = [90, 40, 0, -40, -90]\n'
                             'space = "wall"\np = 5',
                             '[behaviours.follow]\ncomponent = "tally"\n'
                             'reward = "wall-following"\nspace = "wall"')
    cfg = cfg.replace("trials = 2\niterations = 300", "trials = 1\niterations = 40")
    _c, log = run_config(tmp_path, cfg, "tally.h5")
    import tally_plugin

    seen = tally_plugin.SEEN
    assert ("bind", "wall", 4) in seen and ("reset", 4) in seen
    got = {(x[0], x[1], tuple(x[2])) for x in seen if x[0] == "u"}
    assert got == {("u", 4, ("default", "wall"))}
    assert {x for x in seen if x[0] == "learn"} == {("learn", 4)}
    tr = open_log(log).trial(0)
    assert tr.policies["follow"].outputs["turn"].rules.size == 4  # checked against its c


BASE = TWO_SPACES.replace("iterations = 300", "iterations = 20")


@pytest.mark.parametrize(("change", "key", "says"), [
    (('space = "wall"', 'space = "wal"'), "behaviours.follow.space",
     "no situation space 'wal' (did you mean 'wall'?); the config's spaces are: default, wall"),
    (("view = [0, 1, 6, 7]", "view = [0, 1, 6, 9]"), "spaces.wall.view[3]",
     "reading 9 is outside the sensor's 8 readings (indices 0-7"),
    (("[behaviours.avoid]", "[spaces.wall]\ncomponent = \"fcm\"\n\n[behaviours.avoid]"),
     "spaces.wall", "two [spaces.wall] tables"),
    (("[spaces.wall]", "[spaces.default]"), "spaces.default",
     "'default' is the name of the [interpreter]'s space"),
    (('[arbiter]\ncomponent = "cdb"', '[arbiter]\ncomponent = "cdb"\nspace = "none"'),
     "arbiter.space", "no situation space 'none'"),
])
def test_bad_spaces_are_one_line(tmp_path, capsys, change, key, says):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(BASE.replace(*change))
    assert main(["run", str(cfg), "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert f"{cfg}: {key}: " in err and says in err, err
    assert not (tmp_path / "x.h5").exists()


def test_a_clusters_from_space_that_does_not_fit_its_view(two, tmp_path, capsys):
    """Situations fitted on all 8 readings cannot serve a space that sees 4."""
    cfg = tmp_path / "bad.toml"
    cfg.write_text(BASE.replace('collect = { mode = "wander", worlds = ["wall-following"], '
                                'wander_samples = 200 }', f'clusters_from = "{two}"')
                   .replace("c = 4\ntrials = 3\ntransform = \"inverse\"", "c = 6\ntrials = 3"))
    assert main(["run", str(cfg), "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert f"{two}: spaces.wall.view: its situations do not fit the 4 readings of space " \
        "'wall'" in err, err


def test_resume_takes_the_spaces_from_the_log(two, tmp_path):
    """A run stopped after its first trial resumes with the spaces its log holds: the
    resumed trial is bit-identical to the uninterrupted run's."""
    import h5py

    from sitframe.contract.config import load_config
    from sitframe.logs.compare import compare_logs
    from sitframe.runs.prepare import prepare_experiment

    cfg_path = tmp_path / "two.toml"
    cfg_path.write_text(TWO_SPACES)
    cfg, source, base = load_config(str(cfg_path))
    out = tmp_path / "part.h5"
    exp, kw = prepare_experiment(cfg, source=source, base_dir=base, out=str(out))
    exp.run(**kw, trials=[0])
    with h5py.File(out, "a") as f:
        f.attrs["status"] = "aborted"
    assert main(["run", "--resume", str(out), "--workers", "1"]) == 0
    assert open_log(out).trial_indices() == [0, 1]
    assert compare_logs(str(out), str(two)) == []
