"""A config that builds on another run's log makes that run first, or reuses it when it may."""

from __future__ import annotations

import pytest
from helpers import small_config

from sitframe.cli.app import main
from sitframe.contract.config import config_hash, load_config, parse_config, to_toml
from sitframe.errors import InputError
from sitframe.logs.reader import open_log

#: Builds on the situations of base.toml's log; learns only, no evaluation (fast).
DEPENDENT = """
[experiment]
name = "dependent"
trials = 1
iterations = 60
stages = ["learn"]
clusters_from = "logs/base.h5"

[interpreter]
component = "fcm"
c = 4

[behaviours.avoid]
component = "fuzzy-q"
reward = "obstacle-avoidance"

[prerequisites]
"logs/base.h5" = "base.toml"
"""


def _base(seed: int = 3) -> str:
    return small_config(name="base", trials=1, iterations=60, c=4, fcm_trials=2, seed=seed,
                        eval_iterations=20)


@pytest.fixture
def folder(tmp_path, monkeypatch):
    (tmp_path / "base.toml").write_text(_base())
    (tmp_path / "dependent.toml").write_text(DEPENDENT)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_missing_prerequisite_is_made_first_then_reused(folder, capsys):
    assert main(["run", "dependent.toml", "--json"]) == 0
    err = capsys.readouterr().err
    assert "logs/base.h5 not found: running 'base.toml' first to make it" in err
    assert open_log(folder / "logs/base.h5").complete
    assert open_log(folder / "logs/dependent.h5").complete
    # the made log is the prerequisite's config run unchanged
    cfg, _src, _base_dir = load_config(str(folder / "base.toml"))
    assert open_log(folder / "logs/base.h5").attrs["config_hash"] == config_hash(to_toml(cfg))
    assert main(["run", "dependent.toml", "--json"]) == 0
    err = capsys.readouterr().err
    assert "reusing logs/base.h5: a complete log of 'base.toml' (same config)" in err
    assert "not found" not in err and "other code" not in err
    import h5py  # a log of the same config made by other code: reused, and said so

    with h5py.File(folder / "logs/base.h5", "r+") as f:
        f.attrs["code_hash"] = "0" * 64
    assert main(["run", "dependent.toml", "--json"]) == 0
    err = capsys.readouterr().err
    assert "(same config; made by other code than this: remove it to remake it" in err
    # made on a CPU whose numpy computes otherwise: a valid input, reused, and said so
    import json

    from sitframe.runs.arithmetic import arithmetic

    with h5py.File(folder / "logs/base.h5", "r+") as f:
        v = json.loads(f.attrs["versions"])
        f.attrs["versions"] = json.dumps({**v, "numpy_simd": "X86_V2 + OTHER"})
    assert main(["run", "dependent.toml", "--json"]) == 0
    err = capsys.readouterr().err
    assert "blas" in v  # (recorded by the run, so part of what is said)
    made = arithmetic({**v, "numpy_simd": "X86_V2 + OTHER"})
    assert made.startswith(f"numpy {v['numpy']}, SIMD X86_V2 + OTHER, BLAS ")
    assert f"; made with {made}, not this process's {arithmetic()})" in err


def test_prerequisite_made_by_another_config_is_refused(folder, capsys):
    assert main(["run", "base.toml", "--seed", "4", "--out", "logs/base.h5", "--json"]) == 0
    capsys.readouterr()
    assert main(["run", "dependent.toml"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "logs/base.h5" in err and "prerequisites" in err
    assert "was not made by 'base.toml'" in err
    assert not (folder / "logs/dependent.h5").exists()


def test_incomplete_prerequisite_is_refused_with_the_resume_command(folder, capsys):
    assert main(["run", "base.toml", "--out", "logs/base.h5", "--json"]) == 0
    import h5py

    with h5py.File(folder / "logs/base.h5", "a") as f:
        f.attrs["status"] = "aborted"
    capsys.readouterr()
    assert main(["run", "dependent.toml"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sitframe run --resume logs/base.h5" in err


def test_prerequisite_cycle_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for a, b in (("a", "b"), ("b", "a")):
        text = DEPENDENT.replace('"logs/base.h5" = "base.toml"', f'"logs/{b}.h5" = "{b}.toml"')
        (tmp_path / f"{a}.toml").write_text(text.replace("logs/base.h5", f"logs/{b}.h5"))
    assert main(["run", "a.toml"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cycle" in err and "b.toml" in err


def test_prerequisites_table_must_map_paths_to_experiments():
    with pytest.raises(InputError, match=r"prerequisites\.logs/x\.h5.*non-empty string"):
        parse_config(DEPENDENT.replace('"base.toml"', "3").replace("logs/base.h5\" =",
                                                                   "logs/x.h5\" ="))


def test_shipped_presets_name_the_runs_they_build_on():
    for name in ("speed", "goal-finding"):
        cfg, _s, _b = load_config(name)
        reads = {cfg["experiment"]["clusters_from"]} | {
            t["policy_from"]["log"] for t in cfg["behaviours"].values() if "policy_from" in t}
        assert reads - {""} == set(cfg["prerequisites"])
        for run in cfg["prerequisites"].values():
            load_config(run)  # a shipped preset
