"""The plugin tutorial (``docs/tutorials/plugins.md``) runs as written, so it cannot rot.

Its blocks run once, in page order, in an empty folder (module fixture), by the runner
every documentation page uses (``tests/doc_examples.py``: files with a ``title`` are
written, ``console`` blocks run and their output is checked, ``python`` blocks run); the
tests then check what a plugin author relies on beyond the page's own asserts. (The
page is run here rather than collected by Sybil, so that these tests can look at the
folder it ran in.)
"""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from doc_examples import Page, blocks, run_block

from sitframe.cli import main
from sitframe.logs import compare_logs, open_log

DOC = Path(__file__).resolve().parent.parent / "docs" / "tutorials" / "plugins.md"
PAGE = "docs/tutorials/plugins.md"


@pytest.fixture(scope="module")
def tutorial(tmp_path_factory: pytest.TempPathFactory) -> Page:
    """Every block of the tutorial, in page order, in an empty folder."""
    page = Page(tmp_path_factory.mktemp("docs-plugins"), namespace={"__name__": "__doc__"})
    for block in blocks(DOC.read_text("utf-8"), PAGE):
        if block.skip is None:
            run_block(page, block)
    return page


def test_every_example_is_marked() -> None:
    """Every block is code the runner runs, or text; plugin files are written once each."""
    bs = blocks(DOC.read_text("utf-8"), PAGE)
    for b in bs:
        assert b.lang in ("python", "toml", "console", "text", ""), f"{b.where}: {b.lang}"
        assert b.skip is None, f"{b.where}: skipped"
        if b.lang == "toml":
            assert b.title, f"{b.where}: a config the tutorial runs has a file name"
    files = [b.title for b in bs if b.title]
    assert len(files) == len(set(files)), "a file is written twice"
    kinds = {"ring6.py", "prototypes.py", "bumper.py", "bandit.py", "blend.py", "collisions.py"}
    assert kinds <= {Path(f).name for f in files if f.startswith("myplugins/")}


def test_tutorial_runs(tutorial: Page) -> None:
    ran = [" ".join(c.argv) for c in tutorial.commands]
    assert any(r.startswith("--plugins-dir myplugins run tutorial.toml") for r in ran), ran
    assert any(r.startswith("run tutorial.toml --out logs/tutorial-pkg.h5") for r in ran), ran


def test_sensor_geometry_is_logged(tutorial: Page) -> None:
    log = open_log(tutorial.root / "logs" / "tutorial.h5")
    assert log.sensor.name == "ring6"
    assert log.sensor.dim == 6
    np.testing.assert_array_equal(log.sensor.angles_deg, [60, 0, -60, -120, 180, 120])
    assert log.stage("collect")["samples"].shape[1] == 6


def test_observer_and_reward_data_are_in_the_log(tutorial: Page) -> None:
    log = open_log(tutorial.root / "logs" / "tutorial.h5")
    assert log.trial_indices() == [0, 1]
    for k in (0, 1):
        t = log.trial(k)
        hits = np.flatnonzero(t.arrays["collision"])
        np.testing.assert_array_equal(t.plugins["collisions"]["iterations"], hits)
        assert t.plugins["collisions"]["collisions"] == hits.size
        assert t.plugins["bumper"] == {"hits": hits.size}  # from 0 in each trial; no eval
        assert "avoid" in t.policies  # the bandit's LearnedPolicy
    assert log.trial(0).plugins["collisions"]["collisions"] > 0  # the check above can fail


def _load(tutorial: Page, rel: str) -> Any:
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"docs_{Path(rel).stem}", tutorial.root / rel)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_stateful_reward_resets_in_trial_start(tutorial: Page) -> None:
    """One instance through two trials: the count starts again at trial_start."""
    Bumper = _load(tutorial, "myplugins/bumper.py").Bumper
    r = Bumper(margin_radii=2.0)
    r.bind(SimpleNamespace(robot=SimpleNamespace(radius=0.2)))
    assert r.margin == pytest.approx(0.4)
    hit = SimpleNamespace(collided=True, after=SimpleNamespace(nearest=0.0),
                          command=SimpleNamespace(heading_change_deg=0.0))
    r.trial_start(SimpleNamespace(index=0))
    assert [r(hit), r(hit)] == [-30.0, -60.0]
    assert r.trial_end(SimpleNamespace(index=0)) == {"hits": 2}
    r.trial_start(SimpleNamespace(index=1))
    assert r(hit) == -30.0
    assert r.trial_end(SimpleNamespace(index=1)) == {"hits": 1}


def test_arbiter_typo_is_caught_before_collect(tutorial: Page) -> None:
    typo = [c for c in tutorial.commands if "typo.toml" in c.argv]
    assert len(typo) == 1 and typo[0].code == 2
    assert typo[0].err.count("\n") == 1
    assert not (tutorial.root / "logs" / "typo.h5").exists()


def test_broken_reward_keeps_a_failed_log(tutorial: Page) -> None:
    log = open_log(tutorial.root / "logs" / "broken.h5")
    assert log.status == "failed"
    (broken,) = [c for c in tutorial.commands if "broken.toml" in c.argv]
    assert broken.err == f"sitframe: error: {log.failure}\n"


def test_package_route_matches_the_loose_files(tutorial: Page) -> None:
    loose = open_log(tutorial.root / "logs" / "tutorial.h5")
    pkg = open_log(tutorial.root / "logs" / "tutorial-pkg.h5")
    origins = {p["name"]: p for p in pkg.plugins}
    for name in ("ring6", "prototypes", "bumper", "bandit", "blend", "collisions"):
        assert origins[name]["origin"] == "entry point"
        assert origins[name]["distribution"] == "sitframe-tutorial"
    for k in (0, 1):
        a, b = loose.trial(k), pkg.trial(k)
        np.testing.assert_array_equal(a.arrays["pose"], b.arrays["pose"])
        np.testing.assert_array_equal(a.plugins["collisions"]["iterations"],
                                      b.plugins["collisions"]["iterations"])


def test_parameter_error_is_as_documented(tutorial: Page, tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """The message the tutorial quotes for ``max_range = -1`` is the real one."""
    quoted = re.search(r"`(tutorial\.toml: sensor\.max_range: [^`]+)`",
                       " ".join(DOC.read_text("utf-8").split()))
    assert quoted is not None
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("SITFRAME_TRACEBACK", raising=False)
    text = (tutorial.root / "tutorial.toml").read_text()
    Path("tutorial.toml").write_text(text.replace("max_range = 2.0", "max_range = -1"))
    plugins = str(tutorial.root / "myplugins")
    assert main(["--plugins-dir", plugins, "run", "tutorial.toml", "--workers", "1"]) == 2
    assert capsys.readouterr().err == f"sitframe: error: {quoted.group(1)}\n"
    monkeypatch.setenv("SITFRAME_TRACEBACK", "1")  # the traceback instead of the line
    with pytest.raises(ValueError, match=r"sensor\.max_range"):
        main(["--plugins-dir", plugins, "run", "tutorial.toml", "--workers", "1"])


def test_same_log_with_two_workers(tutorial: Page, monkeypatch: pytest.MonkeyPatch,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    """The plugins load in the workers and the observer's data is what it is serially
    (regression: a pool fired ``sitframe_step`` in frozen evaluations, a serial run not)."""
    monkeypatch.chdir(tutorial.root)
    monkeypatch.delenv("SITFRAME_DISABLE_PLUGIN_AUTOLOAD", raising=False)
    assert main(["--plugins-dir", "myplugins", "run", "tutorial.toml", "--out",
                 "logs/tutorial-w2.h5", "--json", "--workers", "2"]) == 0, capsys.readouterr().err
    serial = open_log(tutorial.root / "logs" / "tutorial.h5")
    pool = open_log(tutorial.root / "logs" / "tutorial-w2.h5")
    assert compare_logs(serial.path, pool.path) == []  # bit for bit, plugin data included
    for k in (0, 1):
        a, b = serial.trial(k), pool.trial(k)
        np.testing.assert_array_equal(a.arrays["pose"], b.arrays["pose"])
        assert a.plugins.keys() == b.plugins.keys()
        for plugin, data in a.plugins.items():
            assert data.keys() == b.plugins[plugin].keys(), plugin
            for key, value in data.items():
                np.testing.assert_array_equal(value, b.plugins[plugin][key])


def test_plugin_data_is_everywhere_a_user_looks(tutorial: Page) -> None:
    """The observer's and the reward's per-trial scalars are columns of the exported summary,
    its per-iteration series a column of the iterations, and the report has a section per
    plugin with its scalars and a plot of the series."""
    import csv

    export = tutorial.root / "tutorial-export"
    rows = list(csv.DictReader(open(export / "summary.csv", encoding="utf-8")))
    log = open_log(tutorial.root / "logs" / "tutorial.h5")
    for row in rows:
        t = log.trial(int(row["trial"]))
        assert int(float(row["plugins.collisions.collisions"])) == \
            t.plugins["collisions"]["collisions"]
        assert int(float(row["plugins.bumper.hits"])) == t.plugins["bumper"]["hits"]
    with open(export / "iterations.csv", encoding="utf-8") as fh:
        head = next(csv.reader(fh))
    assert "plugins.collisions.clearance" in head
    assert "plugins.collisions.iterations" not in head  # an array, not a series
    report = tutorial.root / "tutorial-report"
    page = (report / "index.html").read_text("utf-8")
    for sec in ("Plugin &#x27;collisions&#x27;: what it logged",
                "Plugin &#x27;bumper&#x27;: what it logged"):
        assert sec in page
    index = (report / "index.md").read_text("utf-8")
    plots = [line for line in index.splitlines() if "series" in line and "clearance" in line]
    assert len(plots) == 1 and (report / plots[0].split("](")[1].split(")")[0]).stat().st_size
    scalars = (report / "plugin_collisions_scalars.csv").read_text("utf-8")
    assert scalars.splitlines()[0] == "Trial,collisions"
