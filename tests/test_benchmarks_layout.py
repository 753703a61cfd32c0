"""benchmarks/ is grouped by what it measures, and each script says its question and output."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
GROUPS = ("sim", "learning", "logs", "scale", "duel", "report")
SCRIPTS = sorted(p for g in GROUPS for p in (BENCH / g).glob("*.py"))


def test_scripts_live_in_their_groups() -> None:
    loose = sorted(p.name for p in BENCH.glob("*.py"))
    assert loose == [], loose
    assert len(SCRIPTS) >= 20


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_each_script_says_its_question_and_its_output(script: Path) -> None:
    doc = ast.get_docstring(ast.parse(script.read_text("utf-8"))) or ""
    assert "\nQuestion: " in doc and "\nOutput: " in doc, script


def test_a_published_table_names_the_repositorys_files_from_its_root(monkeypatch) -> None:
    import sys

    monkeypatch.syspath_prepend(str(BENCH))
    from common.publish import this_command

    cand = BENCH / "learning" / "preset_candidates" / "wf-p150.toml"
    monkeypatch.setattr(sys, "argv", [str(BENCH / "learning" / "preset_safety.py"), "--presets",
                                      str(cand), "speed", "/elsewhere/x.toml", "logs/a.h5"])
    assert this_command() == (
        "python benchmarks/learning/preset_safety.py --presets "
        "benchmarks/learning/preset_candidates/wf-p150.toml speed /elsewhere/x.toml logs/a.h5")


def test_a_long_measurement_resumes_from_the_seeds_it_cached(tmp_path, monkeypatch,
                                                            capsys) -> None:
    """``common.per_seed``: a seed whose cached result is still fresh is read, not run again;
    a missing or stale one is run, cached and said on stderr."""
    import json

    monkeypatch.syspath_prepend(str(BENCH))
    from common import per_seed

    (tmp_path / "seed-0.json").write_text(json.dumps({"config": "a", "x": 0}))
    (tmp_path / "seed-1.json").write_text(json.dumps({"config": "old", "x": -1}))
    ran: list[int] = []

    def run(seed: int) -> dict:
        ran.append(seed)
        return {"config": "a", "x": seed}

    got = per_seed(range(3), tmp_path, lambda old: old["config"] == "a", run,
                   lambda s, r: f"seed {s}: {r['x']}")
    assert [r["x"] for r in got] == [0, 1, 2] and ran == [1, 2]
    assert json.loads((tmp_path / "seed-1.json").read_text())["x"] == 1
    assert capsys.readouterr().err.splitlines() == ["seed 1: 1", "seed 2: 2"]
    assert [r["x"] for r in per_seed(range(3), tmp_path, lambda old: True, run, str)] == [0, 1, 2]
    assert ran == [1, 2]  # (all cached now)
