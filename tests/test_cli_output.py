"""The plain (non-JSON) output of every command a user reads: run, evaluate,
world list, presets, plugins; and ``SITFRAME_TRACEBACK=1`` showing the traceback (the plain
resume report is in test_resume)."""

from __future__ import annotations

import json
import re

import pytest
from helpers import small_config

from sitframe.cli.app import main
from sitframe.contract.config import list_presets, load_config
from sitframe.logs.reader import open_log
from sitframe.sim.world import list_worlds, load_world


def _cells(out: str, first: str) -> list[list[str]]:
    """The cells of the rich table rows of ``out`` whose first cell is ``first``."""
    rows = []
    for line in out.splitlines():
        cells = [c.strip() for c in re.split(r"[│┃|]", line)[1:-1]]
        if cells and cells[0] == first:
            rows.append(cells)
    return rows


def test_plain_run_and_evaluate(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")  # one table row per line
    cfg = tmp_path / "plain.toml"
    cfg.write_text(small_config(name="plain", trials=2, iterations=200, eval_iterations=50))
    out = tmp_path / "plain.h5"
    capsys.readouterr()
    assert main(["run", str(cfg), "--out", str(out), "--workers", "1"]) == 0
    text = capsys.readouterr().out
    assert re.search(r"plain: 2 trials in \d+\.\d s", text)
    for col in ("trial", "converged at", "collisions", "coll./1000 after conv.", "coverage"):
        assert col in text
    assert "learned rule bases of 2 trials" in text and f"log: {out}" in text
    summary = open_log(out).summary()
    for k in (0, 1):  # each trial's row says what its log says
        (row,) = _cells(text, str(k))
        conv = int(summary["convergence_iteration"][k])
        assert row[1] == (str(conv) if summary["converged"][k] else "not converged")
        assert row[2] == str(int(summary["collisions"][k]))
        assert row[4] == f"{summary['coverage'][k]:.2f}"

    argv = ["evaluate", str(out), "--world", "novel-1", "--iterations", "50"]
    assert main(argv) == 0
    plain = dict(line.split(": ", 1) for line in capsys.readouterr().out.splitlines())
    assert main([*argv, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert {k.strip(): v for k, v in plain.items()} == {k: str(v) for k, v in doc.items()}
    assert doc["iterations"] == 50


def test_piped_run_prints_its_tables_whole(tmp_path, capsys, monkeypatch):
    # Redirected to a file rich would cut the tables to 80 columns; the rule-base table
    # (description + two columns per output) is wider and reached the file as ellipses.
    monkeypatch.delenv("COLUMNS", raising=False)
    cfg = tmp_path / "piped.toml"
    wide = "avoid_obstacles_in_every_room_of_the_laboratory"  # its columns pass 80
    cfg.write_text(small_config(name="piped", trials=2, iterations=200, eval_iterations=50)
                   .replace("[behaviours.avoid]", f"[behaviours.{wide}]"))
    capsys.readouterr()
    assert main(["run", str(cfg), "--out", str(tmp_path / "piped.h5"), "--workers", "1"]) == 0
    text = capsys.readouterr().out
    assert "…" not in text
    assert max(len(line) for line in text.splitlines()) > 80  # (the case this is about)
    assert len(_cells(text, "S1")) == 1  # a situation's row on one line, all its cells


def test_world_list_names_and_describes_every_shipped_world(capsys):
    assert main(["world", "list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list_worlds()
    for line, name in zip(lines, list_worlds(), strict=True):
        assert line.split(None, 1)[1] == load_world(name).description


def test_presets_names_and_describes_every_preset(capsys):
    assert main(["presets"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list_presets()
    assert "obstacle-avoidance" in list_presets() and "wall-following" in list_presets()
    for line, name in zip(lines, list_presets(), strict=True):
        assert line.split(None, 1)[1] == load_config(name)[0]["experiment"]["description"]


def test_plugins_lists_each_built_in_plugin_and_its_components(capsys):
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    blocks = dict(re.findall(r"^(\S+) \(sitframe [^,]+, entry point\)\n((?:    .*\n)*)", out,
                             flags=re.M))
    assert set(blocks) >= {"sonar", "laser", "fcm", "fuzzy-q", "rewards", "arbiters", "goal",
                           "wall-following", "goal-episodes", "hdf5-logger", "progress"}
    assert blocks["fuzzy-q"].split() == ["behaviour", "crisp-q,", "fuzzy-q"]
    assert blocks["arbiters"].split() == ["arbiter", "cdb,", "priority,", "single"]
    assert blocks["rewards"].split() == ["reward", "obstacle-avoidance,", "speed"]
    assert blocks["hdf5-logger"].strip() == "(observer hooks only)"
    assert "CLASH" not in out


def test_traceback_env_shows_the_exception_instead_of_one_line(tmp_path, capsys, monkeypatch):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(small_config().replace("iterations = 300", "iterations = -3"))
    monkeypatch.delenv("SITFRAME_TRACEBACK", raising=False)
    assert main(["run", str(cfg), "--out", str(tmp_path / "x.h5")]) == 2
    line = capsys.readouterr().err
    assert line.count("\n") == 1 and "experiment.iterations" in line
    monkeypatch.setenv("SITFRAME_TRACEBACK", "1")
    with pytest.raises(ValueError, match=r"experiment\.iterations") as info:
        main(["run", str(cfg), "--out", str(tmp_path / "x.h5")])
    assert str(info.value) in line  # the same message, now with its traceback
    assert not (tmp_path / "x.h5").exists()
