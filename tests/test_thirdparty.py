"""A third-party plugin package, installed by pip as a wheel, used as its author would.

``tests/thirdparty/sitframe-thirdparty`` holds one component of every kind -- a 24-beam
360 deg ring (sensor), soft k-means situations (interpreter), a reward that counts near
misses per trial, a tabular Q-learner judged by its own protocol and a wanderer
(behaviours), an activation gate (arbiter), ``sprints`` (an evaluation protocol with its
own config table, ``[sprints]``) -- and an observer that logs near misses and the clearance
of every iteration. The module fixture builds it into a wheel (``tests/wheel.py``),
``pip install``\\ s it into a folder of its own and runs the ``sitframe`` command line in
fresh interpreters that have the folder on ``PYTHONPATH``: the package is found by its
entry points through :mod:`importlib.metadata`, as an installed distribution is, not
loaded from a folder.
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from wheel import build_wheel, pip_install

import sitframe
from sitframe.logs.reader import open_log

PROJECT = Path(__file__).parent / "thirdparty" / "sitframe-thirdparty"

CONFIG = """
[experiment]
name = "tp"
trials = 2
iterations = 200
seed = 4

[sensor]
component = "ring24"

[collect]
worlds = ["collect-1"]

[interpreter]
component = "soft-kmeans"
c = 5

[behaviours.escape]
component = "tabular-q"
reward = "near-miss"

[behaviours.wander]
component = "wanderer"

[arbiter]
component = "gate"
fallback = "wander"
"""
SPRINTS = "\n[sprints]\nepisodes = 3\ndistance = 0.8\n"
#: Bad values of the protocol's table, and the one line each must give.
BAD = {
    "typo": ("distance = 0.8", "distanse = 0.8", "sprints.distanse: unknown key (did you mean "
             "'distance'?); expected one of episodes, timeout, distance, margin, worlds"),
    "range": ("distance = 0.8", "distance = -1", "sprints.distance: expected a number in "
              "(0.0, inf), got -1"),
    "type": ("episodes = 3", 'episodes = "three"', "sprints.episodes: expected an integer in "
             "[1, inf), got str 'three'"),
}


@dataclass
class Installed:
    root: Path
    site: Path
    out: dict[str, subprocess.CompletedProcess[str]]

    def log(self, name: str):
        return open_log(self.root / "logs" / f"{name}.h5")


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    """The package installed by pip, and every command of the scenario, run once."""
    root = tmp_path_factory.mktemp("thirdparty")
    wheel = build_wheel(PROJECT, root / "dist")
    site = root / "site"
    done = pip_install(wheel, site)
    assert done.returncode == 0, done.stderr
    env = {k: v for k, v in os.environ.items()
           if k not in ("SITFRAME_TRACEBACK", "SITFRAME_DISABLE_PLUGIN_AUTOLOAD")}
    # the package's folder, then the sitframe this test imports (the tree under test)
    tree = str(Path(sitframe.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([str(site), tree, *filter(None, [
        os.environ.get("PYTHONPATH")])])
    (root / "tp.toml").write_text(CONFIG + SPRINTS)
    (root / "defaults.toml").write_text(CONFIG.replace('"tp"', '"defaults"'))
    for case, (good, bad, _msg) in BAD.items():
        (root / f"{case}.toml").write_text(CONFIG + SPRINTS.replace(good, bad))
    commands = {
        "plugins": ["plugins"],
        "run": ["run", "tp.toml", "--workers", "1"],
        "run2": ["run", "tp.toml", "--seed", "5", "--out", "logs/tp2.h5", "--workers", "2"],
        "defaults": ["run", "defaults.toml", "--workers", "1", "--json"],
        **{case: ["run", f"{case}.toml", "--workers", "1"] for case in BAD},
        "export": ["export", "logs/tp.h5", "--out", "export"],
        "compare": ["compare", "logs/tp.h5", "logs/tp2.h5", "-o", "cmp", "--json"],
        "analyse": ["analyse", "logs/tp.h5", "-o", "report", "--dpi", "40"],
        "evaluate": ["evaluate", "logs/tp.h5", "--world", "novel-2", "--goal-episodes", "3",
                     "--json"],
    }
    out = {}
    for name, argv in commands.items():
        out[name] = subprocess.run(
            [sys.executable, "-c", "import sys; from sitframe.cli.app import main; "
             "sys.exit(main())", *argv], cwd=root, env=env, capture_output=True, text=True,
            timeout=300)
    return Installed(root, site, out)


def _ok(inst: Installed, name: str) -> subprocess.CompletedProcess[str]:
    done = inst.out[name]
    assert done.returncode == 0, f"{name}: exit {done.returncode}\n{done.stderr}"
    assert "Traceback" not in done.stderr
    return done


def test_the_package_is_an_installed_distribution(installed: Installed) -> None:
    """pip installed it (dist-info with its entry points); sitframe finds every plugin by
    its entry point, with the distribution's name and version, and the table it declares."""
    info = installed.site / "sitframe_thirdparty-0.3.0.dist-info"
    assert (info / "INSTALLER").read_text().strip() == "pip"
    assert "sprints = sitframe_thirdparty.sprints" in (info / "entry_points.txt").read_text()
    text = _ok(installed, "plugins").stdout
    for plugin in ("ring24", "soft-kmeans", "near-miss", "tabular", "gate", "sprints",
                   "nearmiss-log"):
        assert f"{plugin} (sitframe-thirdparty 0.3.0, entry point)" in text
    lines = text.splitlines()
    at = lines.index("sprints (sitframe-thirdparty 0.3.0, entry point)")
    assert lines[at + 1:at + 3] == ["    protocol     sprints", "    table        [sprints]"]
    assert "CLASH" not in text


def test_every_component_kind_runs_and_is_logged(installed: Installed) -> None:
    _ok(installed, "run")
    log = installed.log("tp")
    assert log.status == "complete" and log.sensor.name == "ring24" and log.sensor.dim == 24
    origins = {p["name"]: p for p in log.plugins}
    assert origins["sprints"]["distribution"] == "sitframe-thirdparty"
    assert json.loads(log.attrs["evaluation"]) == {"protocol": "sprints", "worlds": ["novel-1"]}
    for k in (0, 1):
        t = log.trial(k)
        assert "escape" in t.policies and t.arrays["weights"].shape == (200, 2)
        assert t.plugins["near-miss"]["collisions"] == t.arrays["collision"].sum()
        assert t.plugins["nearmiss-log"]["clearance"].shape == (200,)
        assert t.behaviours["escape"]["td_error"].shape == (200,)


def test_a_protocol_with_its_own_table_evaluates_and_logs_it(installed: Installed) -> None:
    """[sprints] is accepted, filled in with its defaults and written with the config, like
    a built-in table; the protocol's episodes and scores are in the log."""
    log = installed.log("tp")
    assert log.config["sprints"] == {"episodes": 3, "timeout": 80, "distance": 0.8,
                                     "margin": 0.1, "worlds": ["novel-1"]}
    t = log.trial(0)
    assert t.episodes["eval/novel-1/first_iteration"].size == 3  # three sprints
    assert 0.0 <= t.summary["eval/novel-1/escape_rate"] <= 1.0
    assert t.episodes["eval/novel-1/escaped"].dtype == bool


def test_a_protocol_whose_table_is_not_given_gets_its_defaults(installed: Installed) -> None:
    _ok(installed, "defaults")
    log = installed.log("defaults")
    assert log.config["sprints"] == {"episodes": 4, "timeout": 80, "distance": 1.0,
                                     "margin": 0.1, "worlds": ["novel-1"]}
    assert log.trial(0).episodes["eval/novel-1/first_iteration"].size == 4


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_key_in_the_protocols_table_is_one_line(installed: Installed, case: str) -> None:
    done = installed.out[case]
    assert done.returncode == 2
    assert done.stderr == f"sitframe: error: {case}.toml: {BAD[case][2]}\n"
    assert not (installed.root / "logs" / f"{case}.h5").exists()


def test_the_protocols_runs_are_evaluated_and_compared(installed: Installed) -> None:
    ev = json.loads(_ok(installed, "evaluate").stdout)
    assert ev["world"] == "novel-2" and 0.0 <= ev["escape_rate"] <= 1.0 and "mean_away_m" in ev
    _ok(installed, "run2")
    cmp = json.loads(_ok(installed, "compare").stdout)
    keys = {m["key"]: m for m in cmp["metrics"]}
    assert "eval.novel-1.coverage" in keys  # (the core's figures of every evaluation)
    for key in ("plugins.nearmiss-log.near_misses", "plugins.nearmiss-log.closest_m",
                "plugins.near-miss.near_misses", "plugins.near-miss.collisions",
                "behaviours.escape.explored"):
        assert keys[key]["family"] == "plugin" and keys[key]["n"] == [2, 2], key


def test_the_observers_data_is_in_the_export_and_the_report(installed: Installed) -> None:
    _ok(installed, "export")
    log = installed.log("tp")
    with open(installed.root / "export" / "summary.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["trial"]) for r in rows] == [0, 1]
    for r in rows:
        t = log.trial(int(r["trial"]))
        assert int(r["plugins.nearmiss-log.near_misses"]) == \
            t.plugins["nearmiss-log"]["near_misses"]
        assert float(r["plugins.nearmiss-log.closest_m"]) == pytest.approx(
            t.plugins["nearmiss-log"]["closest_m"])
        assert float(r["behaviours.escape.explored"]) == pytest.approx(
            t.behaviours["escape"]["explored"])
    with open(installed.root / "export" / "iterations.csv", encoding="utf-8") as fh:
        its = list(csv.DictReader(fh))
    clearance = np.array([float(r["plugins.nearmiss-log.clearance"]) for r in its
                          if r["trial"] == "1"])
    np.testing.assert_allclose(clearance, log.trial(1).plugins["nearmiss-log"]["clearance"])
    assert "behaviours.escape.td_error" in its[0]
    _ok(installed, "analyse")
    report = installed.root / "report"
    page = (report / "index.html").read_text("utf-8")
    assert "Plugin &#x27;nearmiss-log&#x27;: what it logged" in page
    assert "Behaviour &#x27;escape&#x27; (tabular-q): what it logged" in page
    scalars = list(csv.reader(open(report / "plugin_nearmiss-log_scalars.csv")))
    assert scalars[0] == ["Trial", "closest_m", "near_misses"]
    assert [int(row[2]) for row in scalars[1:]] == \
        [log.trial(k).plugins["nearmiss-log"]["near_misses"] for k in (0, 1)]
    figures = sorted(p.name for p in report.glob("plugin_nearmiss-log_series*.png"))
    assert figures == ["plugin_nearmiss-log_series0_clearance.png"]
    assert (report / figures[0]).stat().st_size > 5_000
