"""``docs/plugins.md`` runs as written, so the plugin tutorial cannot rot.

The tutorial's fenced blocks are marked:

* ```` ```python file=PATH ```` / ```` ```toml file=PATH ````: written to ``PATH``;
* ```` ```console ```` (optionally ``exit=N``, default 0): each ``$ COMMAND``
  line is run and the lines after it (up to the next ``$``) must appear in
  its output, in order (``...`` stands for any lines). ``sitframe ...`` runs
  :func:`sitframe.cli.app.main` in-process; ``mkdir``, ``cp`` and ``touch`` run in
  a shell; ``pip install -e DIR`` is emulated without network or touching the
  virtualenv: a ``<name>-<version>.dist-info`` folder with ``METADATA`` and
  ``entry_points.txt`` made from ``DIR/pyproject.toml`` is written to a site
  folder, and every later ``sitframe`` command runs in a subprocess whose
  ``PYTHONPATH`` holds that folder and ``DIR`` (an editable install);
* ```` ```python run ````: executed in-process (its ``assert`` lines are the
  tutorial's claims).

The blocks run once, in document order, in an empty folder (module fixture);
the tests then check what a plugin author relies on beyond the snippets' own
asserts.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from sitframe.cli.app import main
from sitframe.logs.compare import compare_logs
from sitframe.logs.reader import open_log

DOC = Path(__file__).resolve().parent.parent / "docs" / "plugins.md"

_FENCE = re.compile(r"^```(\w*)([^\n]*)\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)


@dataclass(frozen=True)
class Block:
    lang: str
    attrs: dict[str, str]
    text: str
    line: int  # where the block starts in the document (1-based)


def blocks(text: str) -> list[Block]:
    """The fenced blocks of ``text`` with their ``key=value`` / flag attributes."""
    out = []
    for m in _FENCE.finditer(text):
        attrs = {}
        for word in m.group(2).split():
            key, _, value = word.partition("=")
            attrs[key] = value
        out.append(Block(m.group(1), attrs, m.group(3), text.count("\n", 0, m.start()) + 1))
    return out


@dataclass
class Outcome:
    """What one command did."""

    argv: list[str]
    code: int
    out: str
    err: str


@dataclass
class Tutorial:
    root: Path
    commands: list[Outcome] = field(default_factory=list)
    pythonpath: list[str] = field(default_factory=list)

    # -- commands ----------------------------------------------------------
    def sitframe(self, argv: list[str]) -> Outcome:
        if self.pythonpath:  # after an (emulated) pip install: a fresh interpreter
            env = {k: v for k, v in os.environ.items()
                   if k not in ("SITFRAME_TRACEBACK", "SITFRAME_DISABLE_PLUGIN_AUTOLOAD")}
            env["PYTHONPATH"] = os.pathsep.join(self.pythonpath)
            proc = subprocess.run(
                [sys.executable, "-c", "import sys; from sitframe.cli.app import main; "
                 "sys.exit(main())", *argv], cwd=self.root, env=env, capture_output=True,
                text=True, timeout=300)
            return Outcome(argv, proc.returncode, proc.stdout, proc.stderr)
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
        return Outcome(argv, code, out.getvalue(), err.getvalue())

    def pip_install_editable(self, project: str) -> Outcome:
        """Install ``project`` the way ``pip install -e`` makes it visible to importlib.metadata."""
        root = (self.root / project).resolve()
        meta = tomllib.loads((root / "pyproject.toml").read_text())["project"]
        site = self.root / ".site"
        dist = site / f"{meta['name'].replace('-', '_')}-{meta['version']}.dist-info"
        dist.mkdir(parents=True)
        (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {meta['name']}\n"
                                       f"Version: {meta['version']}\n")
        lines = []
        for group, eps in meta.get("entry-points", {}).items():
            lines.append(f"[{group}]")
            lines += [f"{name} = {value}" for name, value in eps.items()]
        (dist / "entry_points.txt").write_text("\n".join(lines) + "\n")
        self.pythonpath = [str(site), str(root)]
        return Outcome(["pip", "install", "-e", project], 0, "", "")

    def shell(self, line: str) -> Outcome:
        proc = subprocess.run(["bash", "-c", line], cwd=self.root, capture_output=True,
                              text=True, timeout=60)
        return Outcome(shlex.split(line), proc.returncode, proc.stdout, proc.stderr)

    def run_command(self, line: str) -> Outcome:
        argv = shlex.split(line)
        if argv[0] == "sitframe":
            return self.sitframe(argv[1:])
        if argv[:3] == ["pip", "install", "-e"] and len(argv) == 4:
            return self.pip_install_editable(argv[3])
        if argv[0] in ("mkdir", "cp", "touch"):
            return self.shell(line)
        raise AssertionError(f"the tutorial runs a command the test cannot: {line!r}")

    # -- blocks ------------------------------------------------------------
    def console(self, block: Block) -> None:
        expected_code = int(block.attrs.get("exit", "0"))
        steps: list[tuple[str, list[str]]] = []
        for line in block.text.splitlines():
            if line.startswith("$ "):
                steps.append((line[2:], []))
            elif line.strip():
                assert steps, f"docs/plugins.md:{block.line}: output before a command"
                steps[-1][1].append(line)
        for command, expected in steps:
            res = self.run_command(command)
            self.commands.append(res)
            code = expected_code if command.startswith("sitframe") else 0
            where = f"docs/plugins.md:{block.line}: $ {command}"
            assert res.code == code, f"{where}: exit {res.code}\n{res.out}\n{res.err}"
            assert "Traceback" not in res.out + res.err, f"{where}:\n{res.err}"
            _in_order(expected, res.out + res.err, where)

    def python(self, block: Block) -> None:
        code = compile(block.text, f"docs/plugins.md:{block.line}", "exec")
        with contextlib.redirect_stdout(io.StringIO()):
            exec(code, {"__name__": "docs_plugins"})  # noqa: S102 - the tutorial's own code


def _norm(line: str) -> str:
    return " ".join(line.split())


def _in_order(expected: list[str], output: str, where: str) -> None:
    """Each expected line (``...`` = anything) is a line of ``output``, in order."""
    lines = [_norm(x) for x in output.splitlines()]
    i = 0
    for want in expected:
        if want.strip() == "...":
            continue
        w = _norm(want)
        while i < len(lines) and lines[i] != w:
            i += 1
        assert i < len(lines), f"{where}: expected the line {want!r} in:\n{output}"
        i += 1


@pytest.fixture(scope="module")
def tutorial(tmp_path_factory: pytest.TempPathFactory) -> Tutorial:
    """Run every block of docs/plugins.md in document order, in an empty folder."""
    root = tmp_path_factory.mktemp("docs-plugins")
    tut = Tutorial(root)
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(root)
        mp.delenv("SITFRAME_TRACEBACK", raising=False)
        mp.delenv("SITFRAME_DISABLE_PLUGIN_AUTOLOAD", raising=False)
        for b in blocks(DOC.read_text("utf-8")):
            if "file" in b.attrs:
                path = root / b.attrs["file"]
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(b.text)
            elif b.lang == "console":
                tut.console(b)
            elif b.lang == "python" and "run" in b.attrs:
                tut.python(b)
    return tut


def test_every_example_is_marked() -> None:
    """No python, toml or console block escapes the test by lacking a marker."""
    bs = blocks(DOC.read_text("utf-8"))
    for b in bs:
        if b.lang in ("python", "toml"):
            assert "file" in b.attrs or (b.lang == "python" and "run" in b.attrs), \
                f"docs/plugins.md:{b.line}: unmarked {b.lang} block"
        else:
            assert b.lang in ("console", "text", ""), f"docs/plugins.md:{b.line}: {b.lang}"
    files = [b.attrs["file"] for b in bs if "file" in b.attrs]
    assert len(files) == len(set(files)), "a file is written twice"
    kinds = {"ring6.py", "prototypes.py", "bumper.py", "bandit.py", "blend.py", "collisions.py"}
    assert kinds <= {Path(f).name for f in files if f.startswith("myplugins/")}


def test_tutorial_runs(tutorial: Tutorial) -> None:
    ran = [" ".join(c.argv) for c in tutorial.commands]
    assert any(r.startswith("--plugins-dir myplugins run tutorial.toml") for r in ran), ran
    assert any(r.startswith("run tutorial.toml --out logs/tutorial-pkg.h5") for r in ran), ran


def test_sensor_geometry_is_logged(tutorial: Tutorial) -> None:
    log = open_log(tutorial.root / "logs" / "tutorial.h5")
    assert log.sensor.name == "ring6"
    assert log.sensor.dim == 6
    np.testing.assert_array_equal(log.sensor.angles_deg, [60, 0, -60, -120, 180, 120])
    assert log.stage("collect")["samples"].shape[1] == 6


def test_observer_and_reward_data_are_in_the_log(tutorial: Tutorial) -> None:
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


def _load(tutorial: Tutorial, rel: str) -> Any:
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"docs_{Path(rel).stem}", tutorial.root / rel)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_stateful_reward_resets_in_trial_start(tutorial: Tutorial) -> None:
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


def test_arbiter_typo_is_caught_before_collect(tutorial: Tutorial) -> None:
    typo = [c for c in tutorial.commands if "typo.toml" in c.argv]
    assert len(typo) == 1 and typo[0].code == 2
    assert typo[0].err.count("\n") == 1
    assert not (tutorial.root / "logs" / "typo.h5").exists()


def test_broken_reward_keeps_a_failed_log(tutorial: Tutorial) -> None:
    log = open_log(tutorial.root / "logs" / "broken.h5")
    assert log.status == "failed"
    (broken,) = [c for c in tutorial.commands if "broken.toml" in c.argv]
    assert broken.err == f"sitframe: error: {log.failure}\n"


def test_package_route_matches_the_loose_files(tutorial: Tutorial) -> None:
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


def test_parameter_error_is_as_documented(tutorial: Tutorial, tmp_path: Path,
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


def test_same_log_with_two_workers(tutorial: Tutorial, monkeypatch: pytest.MonkeyPatch,
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


def test_plugin_data_is_everywhere_a_user_looks(tutorial: Tutorial) -> None:
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
