"""Config tables plugins declare (sitframe.contract.tables): checked, filled in, logged, listed.

The package in tests/thirdparty runs a protocol with its own table as an installed
distribution (tests/test_thirdparty.py); here the same mechanism from plugin folders and
registered plugins: a table only a plugin folder declares, a component other than a
protocol reading its table, the older ``table = "..."`` form, the built-in tables as
declared by their plugins, and every bad declaration as one line naming the plugin.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from sitframe.cli.app import main
from sitframe.contract.config import load_config, parse_config, to_toml
from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.tables import plugin_tables, tables_reference
from sitframe.errors import InputError
from sitframe.logs.reader import open_log

BASE = """
[experiment]
name = "{name}"
trials = 1
iterations = 60
stages = ["collect", "cluster", "learn", "evaluate"]

[collect]
worlds = ["collect-1"]

[interpreter]
component = "fcm"
c = 3
trials = 2

[behaviours.avoid]
component = "fuzzy-q"
reward = "{reward}"

[evaluate]
worlds = ["novel-1"]
iterations = 20
"""

#: A reward that declares a table of its own and reads it in ``bind`` (not a protocol).
SHAPING = '''
from typing import ClassVar

from sitframe import ConfigKey, ConfigTable, RunContext, hookimpl


class Shaped:
    name = "shaped"
    config_table: ClassVar[ConfigTable] = ConfigTable("shaping", (
        ConfigKey("bonus", "number", 1.0, "reward of a step without collision", lo=0.0),
        ConfigKey("penalty", "number", -10.0, "reward of a collision", hi=0.0),
    ), "Rewards of the shaped reward.")

    def bind(self, run: RunContext) -> None:
        self.bonus = run.tables["shaping"]["bonus"]
        self.penalty = run.tables["shaping"]["penalty"]

    def __call__(self, tr) -> float:
        return self.penalty if tr.collided else self.bonus

    def trial_end(self, trial) -> dict:
        return {"bonus": self.bonus}


@hookimpl
def sitframe_rewards() -> list:
    return [Shaped]
'''

#: A protocol of the older form: it names its table; its keys are its keyword arguments.
LAPS = '''
import numpy as np

from sitframe import hookimpl


class Laps:
    name = "laps"
    table = "laps"

    def __init__(self, *, laps: int = 2, length: int = 10) -> None:
        if laps < 1:
            raise ValueError(f"expected laps >= 1, got {laps}")
        self.laps, self.iterations = laps, length

    def episode_starts(self, world, rng, robot):
        return np.tile(world.start, (self.laps, 1)), None

    def terminated(self, context) -> bool:
        return False


class Lapper:
    name = "lapper"
    evaluation_protocol = "laps"

    def reset(self, rng, n_situations, iterations) -> None:
        pass

    def propose(self, context):
        from sitframe import Proposal
        return Proposal(0.0, None)


@hookimpl
def sitframe_protocols() -> list:
    return [Laps]


@hookimpl
def sitframe_behaviours() -> list:
    return [Lapper]
'''


def _plugin(folder: Path, name: str, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.py").write_text(textwrap.dedent(text))
    return folder


def _run(tmp: Path, config: str, plugins: Path | None, capsys, *argv: str) -> tuple[int, str]:
    cfg = tmp / "c.toml"
    cfg.write_text(config)
    extra = ["--plugins-dir", str(plugins)] if plugins is not None else []
    code = main([*extra, "run", str(cfg), "--out", str(tmp / "c.h5"), "--workers", "1",
                 *argv])
    return code, capsys.readouterr().err


def test_the_built_in_tables_are_declared_by_their_plugins():
    """[evaluate] and [goal] are the frozen and goal-episodes plugins' declarations, and a
    config holds them as it always did (text, order, optional keys left out)."""
    reg = Registry.collect(get_plugin_manager())
    index = plugin_tables(reg)
    assert {t: [(k, n) for k, n, _p in o] for t, o in index.owners.items()} == {
        "evaluate": [("protocol", "frozen")], "goal": [("protocol", "goal-episodes")]}
    cfg = parse_config('[behaviours.a]\ncomponent = "fuzzy-q"\n')
    assert list(cfg) == ["experiment", "robot", "sensor", "collect", "interpreter",
                         "behaviours", "arbiter", "evaluate", "goal", "plugins"]
    assert cfg["evaluate"] == {"worlds": ["training", "novel-1", "novel-2"], "iterations": 1000}
    assert "train" not in cfg["goal"] and cfg["goal"]["episodes"] == 50
    with pytest.raises(InputError, match=r"f.toml: goal.train: expected one of 'world', 'ep"):
        parse_config('[behaviours.a]\ncomponent = "fuzzy-q"\n[goal]\ntrain = "epsiodes"\n',
                     file="f.toml")
    ref = tables_reference(index, reg)
    assert "### `[goal]`" in ref and "Declared by protocol 'goal-episodes' of plugin " \
        "goal-episodes (sitframe" in ref
    assert "| `min_distance` | number | 3 | m | [0, inf) |" in ref


def test_plugins_tables_command_lists_the_declarations(capsys, tmp_path):
    plugins = _plugin(tmp_path / "p", "shaping", SHAPING)
    assert main(["--plugins-dir", str(plugins), "plugins", "--tables"]) == 0
    out = capsys.readouterr().out
    assert "### `[shaping]`" in out and "Declared by reward 'shaped' of plugin shaping (" in out
    assert "| `penalty` | number | -10 |  | (-inf, 0] | reward of a collision |" in out


def test_a_component_reads_its_table_and_the_log_keeps_it(tmp_path, capsys):
    """A reward (not a protocol) declares [shaping]: a run that uses the reward gets the
    table filled in and logged; its values reach the reward in bind."""
    plugins = _plugin(tmp_path / "p", "shaping", SHAPING)
    code, err = _run(tmp_path, BASE.format(name="s", reward="shaped") +
                     "\n[shaping]\nbonus = 2.5\n", plugins, capsys)
    assert code == 0, err
    log = open_log(tmp_path / "c.h5")
    assert log.config["shaping"] == {"bonus": 2.5, "penalty": -10.0}
    assert log.trial(0).plugins["shaping"] == {"bonus": 2.5}
    assert set(log.trial(0).arrays["reward/avoid"]) <= {2.5, -10.0}
    # not given: its defaults, in the log too
    code, err = _run(tmp_path, BASE.format(name="s", reward="shaped"), plugins, capsys)
    assert code == 0, err
    assert open_log(tmp_path / "c.h5").config["shaping"] == {"bonus": 1.0, "penalty": -10.0}
    # a run that does not use the reward does not get the table (its text stays as it was)
    code, err = _run(tmp_path, BASE.format(name="s", reward="obstacle-avoidance"), plugins,
                     capsys)
    assert code == 0, err
    assert "shaping" not in open_log(tmp_path / "c.h5").config


@pytest.mark.parametrize("line, message", [
    ("bonus = -1", "c.toml: shaping.bonus: expected a number in [0.0, inf), got -1"),
    ("bonsu = 1", "c.toml: shaping.bonsu: unknown key (did you mean 'bonus'?)"),
    ("bonus = 'x'", "c.toml: shaping.bonus: expected a number in [0.0, inf), got str 'x'"),
])
def test_a_bad_key_in_a_folder_plugins_table_is_one_line(tmp_path, capsys, line, message):
    """A table only a plugin folder declares is checked once the folder is loaded."""
    plugins = _plugin(tmp_path / "p", "shaping", SHAPING)
    code, err = _run(tmp_path, BASE.format(name="s", reward="shaped") + f"\n[shaping]\n{line}\n",
                     plugins, capsys)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"sitframe: error: {tmp_path / message}")
    assert not (tmp_path / "c.h5").exists()


def test_a_table_no_plugin_declares_is_an_unknown_section(tmp_path, capsys):
    plugins = _plugin(tmp_path / "p", "shaping", SHAPING)
    code, err = _run(tmp_path, BASE.format(name="s", reward="shaped") + "\n[shapping]\n",
                     plugins, capsys)
    assert code == 2 and err.count("\n") == 1
    assert "shapping: unknown section (did you mean 'shaping'?)" in err
    # without the plugin folder the table is unknown too, found before any plugin loads
    with pytest.raises(InputError, match=r"shaping: unknown section; expected one of .*goal"):
        parse_config(BASE.format(name="s", reward="shaped") + "\n[shaping]\nbonus = 1\n")


def test_a_protocol_naming_its_table_gets_one_from_its_signature(tmp_path, capsys):
    """The older form (``table = "laps"``, no declaration): the table's keys are the
    protocol's keyword arguments and ``worlds``; it is accepted, checked and logged."""
    plugins = _plugin(tmp_path / "p", "laps", LAPS)
    config = BASE.format(name="l", reward="obstacle-avoidance").replace(
        'component = "fuzzy-q"\nreward = "obstacle-avoidance"', 'component = "lapper"')
    code, err = _run(tmp_path, config.replace('"learn", ', "") + "\n[laps]\nlaps = 3\n"
                     'worlds = ["novel-2"]\n', plugins, capsys)
    assert code == 0, err
    log = open_log(tmp_path / "c.h5")
    assert log.config["laps"] == {"laps": 3, "worlds": ["novel-2"]}
    assert log.trial(0).episodes["first_iteration"].tolist() == [0, 10, 20]
    code, err = _run(tmp_path, config + "\n[laps]\nlasp = 3\n", plugins, capsys)
    assert code == 2 and "c.toml: laps.lasp: unknown key (did you mean 'laps'?)" in err
    code, err = _run(tmp_path, config + "\n[laps]\nlaps = 0\nworlds = ['novel-1']\n", plugins,
                     capsys)
    assert code == 2 and "c.toml: laps: expected laps >= 1, got 0" in err
    code, err = _run(tmp_path, config, plugins, capsys)  # no table: no worlds to run it in
    assert code == 2 and err.count("\n") == 1 and "c.toml: laps.worlds: missing" in err


CLASHES = {
    "core": ('ConfigTable("sensor", ())',
             "plugin bad ({dir}/bad.py): protocol 'bad': config_table declares [sensor], which "
             "is the core's own table"),
    "built-in": ('ConfigTable("goal", (ConfigKey("iterations", "integer", 5),))',
                 "config table [goal] is declared by two plugins: goal-episodes (sitframe 0.1.0,"
                 " entry point) (protocol 'goal-episodes') and bad ({dir}/bad.py) (protocol "
                 "'bad')"),
    "not-taken": ('ConfigTable("bad", (ConfigKey("speed", "number", 1.0),))',
                  "plugin bad ({dir}/bad.py): protocol 'bad': config_table [bad] declares "
                  "'speed', which the protocol does not take (its parameters: iterations)"),
    "not-a-table": ('{"episodes": 3}',
                    "plugin bad ({dir}/bad.py): protocol 'bad': config_table is dict "
                    "{{'episodes': 3}}, expected a sitframe.ConfigTable"),
    "bad-kind": ('ConfigTable("bad", (ConfigKey("iterations", "int", 1),))',
                 "plugin bad ({dir}/bad.py): protocol 'bad': config_table [bad]: key "
                 "'iterations' has kind 'int', expected one of"),
}


@pytest.mark.parametrize("case", list(CLASHES))
def test_a_bad_declaration_is_one_line_naming_the_plugin(tmp_path, capsys, case):
    decl, message = CLASHES[case]
    plugins = _plugin(tmp_path / "p", "bad", f'''
        from sitframe import ConfigKey, ConfigTable, hookimpl


        class Bad:
            name = "bad"
            config_table = {decl}

            def __init__(self, *, iterations: int = 5) -> None:
                self.iterations = iterations

            def episode_starts(self, world, rng, robot):
                return None

            def terminated(self, context) -> bool:
                return False


        @hookimpl
        def sitframe_protocols() -> list:
            return [Bad]
        ''')
    code, err = _run(tmp_path, BASE.format(name="b", reward="obstacle-avoidance"), plugins,
                     capsys)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("sitframe: error: " + message.format(dir=plugins)), err
    assert not (tmp_path / "c.h5").exists()


def test_two_folder_plugins_declaring_one_table_is_one_line(tmp_path, capsys):
    one = 'from sitframe import ConfigKey, ConfigTable, hookimpl\n\n\nclass {cls}:\n' \
          '    name = "{name}"\n    config_table = ConfigTable("shared", (ConfigKey("x", ' \
          '"number", {x}),))\n\n    def __call__(self, tr):\n        return 0.0\n\n\n' \
          '@hookimpl\ndef sitframe_rewards():\n    return [{cls}]\n'
    plugins = tmp_path / "p"
    _plugin(plugins, "first", one.format(cls="A", name="a", x=1.0))
    _plugin(plugins, "second", one.format(cls="B", name="b", x=2.0))
    code, err = _run(tmp_path, BASE.format(name="t", reward="obstacle-avoidance"), plugins,
                     capsys)
    assert code == 2 and err.count("\n") == 1
    assert err == (f"sitframe: error: config table [shared] is declared by two plugins: first "
                   f"({plugins}/first.py) (reward 'a') and second ({plugins}/second.py) "
                   "(reward 'b'); expected one declaration per table\n")


def test_every_preset_keeps_its_text():
    """A preset's config text is what it was before protocols declared their tables (the
    log's config, and so its hash, are unchanged)."""
    cfg, _s, _b = load_config("goal-finding-learned")
    text = to_toml(cfg)
    assert text.index("[arbiter]") < text.index("[evaluate]") < text.index("[goal]") \
        < text.index("[plugins]") < text.index("[prerequisites]")
    goal = text[text.index("[goal]"):text.index("[plugins]")]  # defaults, then the given
    assert goal.splitlines()[1:9] == ["episodes = 50", "timeout = 300", "min_distance = 3.0",
                                      'worlds = ["goal", "novel-1", "novel-2", "multi-room", '
                                      '"u-trap"]', 'pairs = "random"', "radius = 0.3",
                                      "margin = 0.3", 'train = "episodes"']


def test_a_protocol_without_a_table_gets_its_defaults(tmp_path):
    """No table at all: its parameters' defaults, and the default protocol's worlds."""
    import numpy as np

    from sitframe import Proposal, hookimpl
    from sitframe.contract.config import validate_config
    from sitframe.runs.experiment import Experiment

    class Twice:
        name = "twice"

        def __init__(self, *, length: int = 7) -> None:
            self.iterations = length

        def episode_starts(self, world, rng, robot):
            return np.tile(world.start, (2, 1)), None

        def terminated(self, context) -> bool:
            return False

    class Still:
        name = "still"
        evaluation_protocol = "twice"

        def reset(self, rng, n_situations, iterations) -> None:
            pass

        def propose(self, context):
            return Proposal(0.0, 0.0)

    class Plugin:
        @hookimpl
        def sitframe_protocols(self) -> list:
            return [Twice]

        @hookimpl
        def sitframe_behaviours(self) -> list:
            return [Still]

    pm = get_plugin_manager(plugins=[Plugin()])
    cfg = validate_config({"experiment": {"stages": ["evaluate"]},
                           "interpreter": {"component": "fcm", "c": 2},
                           "behaviours": {"s": {"component": "still"}},
                           "evaluate": {"worlds": ["novel-1"]}})
    exp = Experiment(cfg, pm=pm)
    assert exp.protocol == "twice" and exp.eval_worlds == ["novel-1"]
    state = {"centers": np.array([[0.5] * 8, [3.0] * 8]), "m": 1.2}
    (trial,) = exp.run(interpreter_state=state).trials
    assert trial.episodes["first_iteration"].tolist() == [0, 7]
