"""Plugin contract v2: the public face, the lifecycle, learned policies, plugin data, discovery."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from helpers import run_config, run_json, small_config

import sitframe
from sitframe.cli.app import main
from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.records import Context, Proposal
from sitframe.logs.reader import open_log

ROOT = Path(__file__).resolve().parent.parent


def test_every_public_name_resolves_and_import_stays_light():
    for name in sitframe.__all__:
        assert getattr(sitframe, name) is not None, name
    code = ("import sys, sitframe; print(sorted(m for m in ('sitframe.runs.experiment', "
            "'sitframe.logs', 'h5py', 'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"  # attributes load on first use only


@pytest.mark.parametrize("path", sorted((ROOT / "plugins").glob("*.py")), ids=lambda p: p.name)
def test_builtin_plugins_import_only_the_top_level_package(path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and \
                node.module.startswith("sitframe"):
            assert node.module == "sitframe", f"{path.name}:{node.lineno} imports {node.module}"
        if isinstance(node, ast.Import):
            assert not any(a.name.startswith("sitframe.") for a in node.names), path.name


# A third-party plugin module using every new seam at once.
SEAMS = '''
import numpy as np
from sitframe import LearnedPolicy, PolicyOutput, Proposal, hookimpl

EVENTS = []


class Stateful:
    """A reward whose state is reset at each trial start; it reads the radius at bind."""
    name = "stateful"

    def bind(self, run):
        self.radius = run.robot.radius
        self.labels = run.labels
        self.dim = run.sensor.dim

    def trial_start(self, trial):
        self.calls = 0
        EVENTS.append(("start", trial.index, trial.kind))

    def __call__(self, tr):
        self.calls += 1
        return -1.0 if tr.collided else 1.0

    def trial_end(self, trial):
        return {"reward_calls": self.calls, "radius": self.radius, "dim": self.dim}


class Table:
    """A learned behaviour of its own: a random rule base, 'learned' as a LearnedPolicy."""
    name = "table-learner"
    headings = np.array([45.0, 0.0, -45.0])

    def reset(self, rng, n_situations, iterations):
        if getattr(self, "fixed", None) is None:
            self.rules = rng.integers(0, 3, n_situations)

    def load_policy(self, policy):
        self.fixed = policy.outputs["heading"].rules
        self.rules = self.fixed

    def propose(self, ctx):
        return Proposal(float(self.headings[self.rules[int(ctx.memberships.argmax())]]), None,
                        activation=float(ctx.memberships.max()))

    def learn(self, tr, r):
        pass

    def policy(self):
        return LearnedPolicy({"heading": PolicyOutput(self.headings, self.rules, "deg")})


@hookimpl
def sitframe_rewards():
    return [Stateful]


@hookimpl
def sitframe_behaviours():
    return [Table]


STEPS = {}


@hookimpl
def sitframe_step(record):
    STEPS[record.trial] = STEPS.get(record.trial, 0) + 1


@hookimpl
def sitframe_trial_data(trial):
    return {"steps": np.asarray([STEPS.pop(trial.index, 0)]), "nested/deeper/x": 1.5}
'''


def _seams_config() -> str:
    return small_config(trials=2, iterations=60).replace(
        'component = "fuzzy-q"\nreward = "obstacle-avoidance"\np = 5',
        'component = "table-learner"\nreward = "stateful"')


@pytest.mark.parametrize("workers", ["1", "2"])
def test_new_learned_behaviour_plugin_data_and_step_observers_in_any_process(
        tmp_path, capsys, workers):
    plug = tmp_path / "plug"
    plug.mkdir()
    (plug / "seams.py").write_text(SEAMS)
    cfg = tmp_path / "c.toml"
    cfg.write_text(_seams_config())
    out = tmp_path / "log.h5"
    doc = run_json(capsys, "--plugins-dir", str(plug), "run", str(cfg), "--out", str(out),
                   "--json", "--workers", workers)
    # --json shows the new behaviour's rule base as headings, not action indices
    rb = doc["trials"][0]["rule_base"]["avoid.heading"]
    assert len(rb) == 6 and set(rb) <= {45.0, 0.0, -45.0}
    log = open_log(out)
    for k in (0, 1):
        tr = log.trial(k)
        data = tr.plugins["seams"]
        # the stateful reward was reset per trial and bound to the run
        assert data["reward_calls"] == 60
        assert data["radius"] == 0.15 and data["dim"] == 8
        # sitframe_step fired in whichever process simulated the trial
        assert np.array_equal(data["steps"], [60])
        assert data["nested/deeper/x"] == 1.5
        assert "eval/novel-1/reward_calls" not in data  # evaluations do not learn
        pol = tr.learned_policy("avoid")
        assert pol.outputs["heading"].unit == "deg"
        assert tr.arrays["reading"].shape == (60, 8)
    assert log.sensor.dim == 8 and log.sensor.name == "pioneer-sonar"
    if workers != "1":  # (the same log either way: evaluate and analyse it once)
        return
    # evaluate and analyse treat it like any learned behaviour
    ev = run_json(capsys, "--plugins-dir", str(plug), "evaluate", str(out), "--world",
                  "novel-2", "--iterations", "30", "--json")
    assert ev["iterations"] == 30
    assert main(["--plugins-dir", str(plug), "analyse", str(out), "-o",
                 str(tmp_path / "an")]) == 0
    assert "45" in (tmp_path / "an" / "rule_bases.md").read_text()


def test_policy_from_refuses_a_policy_learned_with_other_actions(tmp_path, capsys):
    _cfg, log = run_config(tmp_path, small_config(trials=1, iterations=60), "a.h5")
    capsys.readouterr()
    text = small_config(trials=1, iterations=60).replace(
        'p = 5', f'p = 5\nheadings = [90, 0, -90]\npolicy_from = {{log = "{log}", trial = 0}}')
    (tmp_path / "b.toml").write_text(text)
    # found when the run is set up (it was a failed log, in its first trial): exit 2, no log
    assert main(["run", str(tmp_path / "b.toml"), "--out", str(tmp_path / "b.h5")]) == 2
    err = capsys.readouterr().err
    assert "differ from this behaviour's headings" in err and err.count("\n") == 1
    assert "a.h5: behaviours.avoid.policy_from: its policy does not fit behaviour 'avoid'" in err
    assert not (tmp_path / "b.h5").exists()


def test_crisp_q_executes_the_dominant_rule_alone(tmp_path, capsys):
    text = small_config(trials=1, iterations=200).replace('"fuzzy-q"', '"crisp-q"')
    _cfg, log = run_config(tmp_path, text, "crisp.h5")
    tr = open_log(log).trial(0)
    headings = {90.0, 60.0, 30.0, 0.0, -30.0, -60.0, -90.0}
    # no blending: every proposal is one of the singletons exactly
    assert set(np.unique(tr.arrays["proposals/avoid"][:, 0])) <= headings
    # only the dominant situation's rule is ever updated
    dom = np.bincount(tr.arrays["memberships"].argmax(axis=1), minlength=6)
    upd = tr.behaviours["avoid"]["heading/updates"]
    assert np.all(upd <= dom) and upd.sum() > 0


def test_priority_arbiter_uses_activation_where_given():
    from sitframe.plugins.arbiters import PriorityArbiter

    arb = PriorityArbiter(threshold=0.5, activation=0.6)
    ctx = Context(0, np.zeros(3), np.ones(8), np.ones(1), 2.0, None)
    goal = Proposal(10.0)
    # far from everything: the avoider wins anyway when it says it is needed
    _p, w = arb.combine(ctx, {"avoid": Proposal(-50.0, activation=0.9), "goal": goal})
    assert w.tolist() == [1.0, 0.0]
    _p, w = arb.combine(ctx, {"avoid": Proposal(-50.0, activation=0.1), "goal": goal})
    assert w.tolist() == [0.0, 1.0]
    # without an activation the distance rule decides, as before
    _p, w = arb.combine(ctx, {"avoid": Proposal(-50.0), "goal": goal})
    assert w.tolist() == [0.0, 1.0]
    explicit = PriorityArbiter(rules=[{"behaviour": "avoid", "activation_above": 0.5},
                                      {"behaviour": "goal"}])
    _p, w = explicit.combine(ctx, {"avoid": Proposal(-50.0, activation=0.5), "goal": goal})
    assert w.tolist() == [1.0, 0.0]


def test_arbiter_rule_typo_is_found_at_binding_before_collect(tmp_path, capsys):
    text = small_config(trials=1) + '\n[arbiter]\ncomponent = "priority"\n' \
        'rules = [{behaviour = "avod"}]\n'
    (tmp_path / "c.toml").write_text(text)
    out = tmp_path / "c.h5"
    assert main(["run", str(tmp_path / "c.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "arbiter.rules[0].behaviour" in err and "'avod'" in err
    assert not out.exists()  # nothing ran, nothing was written


LEARNING_ARBITER = '''
import numpy as np
from sitframe import LearnedPolicy, PolicyOutput, Proposal, hookimpl


class Learner:
    """Learns which behaviour to trust per situation (a counting stand-in for Q-learning)."""
    name = "counting"

    def bind(self, run):
        self.k = len(run.labels)

    def reset(self, rng, n_situations, iterations):
        self.score = np.zeros((n_situations, self.k))
        if getattr(self, "frozen", None) is not None:  # evaluated as it learned
            self.score[np.arange(n_situations), self.frozen] = 1.0

    def combine(self, ctx, proposals):
        s = int(ctx.memberships.argmax())
        w = np.zeros(self.k)
        w[int(self.score[s].argmax())] = 1.0
        p = list(proposals.values())[int(w.argmax())]
        self.last = (s, int(w.argmax()))
        return p, w

    def learn(self, tr, r):
        self.score[self.last] += r

    def policy(self):
        return LearnedPolicy({"weight": PolicyOutput(np.arange(self.k, dtype=float),
                                                     self.score.argmax(axis=1))})

    def load_policy(self, policy):
        self.frozen = policy.outputs["weight"].rules


@hookimpl
def sitframe_arbiters():
    return [Learner]
'''


def test_an_arbiter_can_learn_from_a_reward(tmp_path, capsys):
    plug = tmp_path / "plug"
    plug.mkdir()
    (plug / "learner.py").write_text(LEARNING_ARBITER)
    text = small_config(trials=1, iterations=80) + textwrap.dedent('''
        [behaviours.straight]
        component = "fuzzy-q"
        headings = [0]
        learn = []
        policy_from = {log = "unused"}
        ''')
    text = text.replace('\n[behaviours.straight]', '\n[arbiter]\ncomponent = "counting"\n'
                        'reward = "obstacle-avoidance"\n\n[behaviours.straight]')
    text = text.replace('policy_from = {log = "unused"}\n', '')
    text = text.replace('learn = []', 'learn = ["heading"]\nreward = "obstacle-avoidance"')
    (tmp_path / "c.toml").write_text(text)
    out = tmp_path / "c.h5"
    assert main(["--plugins-dir", str(plug), "run", str(tmp_path / "c.toml"), "--out",
                 str(out), "--workers", "1"]) == 0, capsys.readouterr().err
    tr = open_log(out).trial(0)
    assert tr.arrays["reward/arbiter"].shape == (80,)
    assert tr.learned_policy("arbiter").outputs["weight"].rules.shape == (6,)


def test_duplicate_entry_point_names_are_reported_not_dropped(tmp_path, monkeypatch, capsys):
    site = tmp_path / "site"
    site.mkdir()
    for dist in ("alpha", "beta"):
        (site / f"{dist}_plug.py").write_text(textwrap.dedent(f'''
            from sitframe import hookimpl

            class R:
                name = "{dist}-reward"
                def __call__(self, tr):
                    return 0.0

            @hookimpl
            def sitframe_rewards():
                return [R]
            '''))
        info = site / f"{dist}-1.0.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.0\n")
        (info / "entry_points.txt").write_text(f"[sitframe]\nsame = {dist}_plug\n")
    monkeypatch.syspath_prepend(str(site))
    reg = Registry.collect(get_plugin_manager(autoload=True))
    assert {"alpha-reward", "beta-reward"} <= set(reg.names("reward"))
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "CLASH: entry point 'same' is declared by" in out


def test_plugins_lists_everything_when_components_clash(tmp_path, capsys):
    (tmp_path / "dup.py").write_text(textwrap.dedent('''
        from sitframe import hookimpl

        class Again:
            name = "obstacle-avoidance"
            def __call__(self, tr):
                return 0.0

        @hookimpl
        def sitframe_rewards():
            return [Again]
        '''))
    assert main(["--plugins-dir", str(tmp_path), "plugins"]) == 0
    out = capsys.readouterr().out
    assert "fuzzy-q" in out and "CLASH: reward name 'obstacle-avoidance'" in out
    # a run still refuses the clash, naming both plugins
    cfg = tmp_path / "c.toml"
    cfg.write_text(small_config(trials=1))
    assert main(["--plugins-dir", str(tmp_path), "run", str(cfg), "--out",
                 str(tmp_path / "x.h5")]) == 2
    assert "registered by two plugins" in capsys.readouterr().err


def test_sensor_spec_and_plugin_data_are_in_the_log_attributes(tmp_path, capsys):
    _cfg, log = run_config(tmp_path, small_config(trials=1, iterations=40), "s.h5")
    lg = open_log(log)
    spec = json.loads(lg.attrs["sensor"])
    assert spec["dim"] == 8 and spec["angles_deg"][0] == 90.0 and spec["max_range"] == 3.0
    assert lg.failure is None and lg.complete


SIX_BEAMS = '''
import numpy as np
from sitframe import hookimpl
from sitframe.plugins.sonar import SonarRing


class Six(SonarRing):
    name = "six"
    BEAMS = 6

    def __init__(self, **kw):
        super().__init__(**kw)
        self.angles_deg = self.angles_deg[: self.BEAMS]

    def read(self, world, pose, rng):
        return super().read(world, pose, rng)[: self.BEAMS]


@hookimpl
def sitframe_sensors():
    return [Six]
'''


def test_evaluate_names_a_missing_or_changed_sensor_plugin(tmp_path, capsys):
    plug = tmp_path / "plug"
    plug.mkdir()
    (plug / "six.py").write_text(SIX_BEAMS)
    text = small_config(trials=1, iterations=40, c=4, fcm_trials=2) + \
        '\n[sensor]\ncomponent = "six"\n\n[plugins]\ndirs = ["plug"]\n'
    _cfg, log = run_config(tmp_path, text, "a.h5", "--workers", "1")
    capsys.readouterr()
    # without its plugin: the error says which plugin the log was written with
    assert main(["evaluate", str(log), "--world", "novel-1", "--iterations", "10"]) == 2
    err = capsys.readouterr().err
    assert "unknown sensor 'six'" in err and "the log was written with plugins not loaded " \
        "now: six (" in err and "six.py)" in err, err
    (plug / "six.py").write_text(SIX_BEAMS.replace("BEAMS = 6", "BEAMS = 7"))
    # was blamed on the interpreter (a shape error in memberships), exit 3
    assert main(["--plugins-dir", str(plug), "evaluate", str(log), "--world", "novel-1",
                 "--iterations", "10"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a.h5: sensor: its situations were fitted on readings of " \
        "sensor 'six' (6 beams" in err and "now has 7" in err, err


MEASURING_REWARD = '''
from sitframe import hookimpl
from sitframe.plugins.rewards import ObstacleAvoidanceReward


class Measuring(ObstacleAvoidanceReward):
    name = "measuring"

    def metrics(self, arrays):
        return {"band": arrays["no-such-array"]}


@hookimpl
def sitframe_rewards():
    return [Measuring]
'''


def test_a_reward_metrics_fault_in_evaluate_names_the_reward(tmp_path, capsys):
    plug = tmp_path / "plug"
    plug.mkdir()
    (plug / "measuring.py").write_text(MEASURING_REWARD)
    text = small_config(trials=1, iterations=40, c=4, fcm_trials=2, eval_iterations=10).replace(
        'reward = "obstacle-avoidance"', 'reward = "measuring"') + \
        '\n[plugins]\ndirs = ["plug"]\n'
    _cfg, log = run_config(tmp_path, text, "a.h5", "--workers", "1")
    capsys.readouterr()
    # was "a.h5: the log's contents are damaged or not laid out as a sitframe log (KeyError...)"
    assert main(["--plugins-dir", str(plug), "evaluate", str(log), "--world", "novel-1",
                 "--iterations", "10"]) == 3
    err = capsys.readouterr().err
    assert "reward 'measuring' [behaviours.avoid.reward]: metrics(): KeyError: 'no-such-array'" \
        in err and err.count("\n") == 1, err
