"""Run-config validation: one clear error per bad input, with file and key path."""

from __future__ import annotations

import tomllib

import pytest

from sitframe.contract.config import list_presets, load_config, parse_config, to_toml
from sitframe.errors import InputError

MINIMAL = '[behaviours.avoid]\ncomponent = "fuzzy-q"\nreward = "obstacle-avoidance"\n'


def test_presets_load_and_round_trip():
    assert {"obstacle-avoidance", "obstacle-avoidance-12", "speed"} <= set(list_presets())
    for name in list_presets():
        cfg, source, _ = load_config(name)
        assert source == f"preset:{name}"
        again = parse_config(to_toml(cfg))
        assert again == cfg


def test_defaults_are_table_a1():
    cfg = parse_config(MINIMAL)
    assert cfg["experiment"]["trials"] == 11
    assert cfg["experiment"]["iterations"] == 5000
    assert cfg["experiment"]["default_speed"] == 0.15


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("", r"f.toml: config is empty"),
        ("[experiment\n", r"f.toml: not valid TOML"),
        ("[experimnt]\n" + MINIMAL, r"f.toml: experimnt: unknown section \(did you mean "
                                    r"'experiment'\?\)"),
        ("[experiment]\ntrails = 3\n" + MINIMAL, r"experiment.trails: unknown key \(did you "
                                                 r"mean 'trials'\?\)"),
        ("[experiment]\ntrials = 0\n" + MINIMAL, r"experiment.trials: expected an integer in "
                                                 r"\[1, inf\), got 0"),
        ("[experiment]\ntrials = 'x'\n" + MINIMAL, r"experiment.trials: expected an integer .*"
                                                   r"got str 'x'"),
        ("[experiment]\ndefault_speed = nan\n" + MINIMAL, r"experiment.default_speed: .*"
                                                          r"non-finite"),
        ("[experiment]\nstages = ['lern']\n" + MINIMAL, r"experiment.stages\[0\]: expected one "
                                                        r"of .* got 'lern' \(did you mean"),
        ("[experiment]\nseed = 1\n", r"behaviours: no behaviours configured"),
        ("[behaviours.avoid]\nreward = 'x'\n", r"behaviours.avoid: missing 'component'"),
        ("[robot]\nradus = 0.2\n" + MINIMAL, r"robot.radus: unknown key \(did you mean "
                                             r"'radius'\?\)"),
        ("[collect]\nworlds = []\n" + MINIMAL, r"collect.worlds: expected a non-empty list"),
        ("[behaviours.avoid]\ncomponent = 'fuzzy-q'\npolicy_from = {lg = 'x'}\n",
         r"behaviours.avoid.policy_from: expected a table"),
    ],
)
def test_bad_configs(text, pattern):
    with pytest.raises(InputError, match=pattern):
        parse_config(text, file="f.toml")


def test_unknown_preset_lists_available():
    with pytest.raises(InputError, match=r"unknown experiment 'obstacle-avoid'.*available "
                                         r"presets: .*obstacle-avoidance-12"):
        load_config("obstacle-avoid")


def test_missing_config_file(tmp_path):
    with pytest.raises(InputError, match=r"config file not found"):
        load_config(str(tmp_path / "nope.toml"))


def test_to_toml_is_valid_toml():
    cfg, _, _ = load_config("speed")
    text = to_toml(cfg)
    assert tomllib.loads(text)["behaviours"]["avoid"]["policy_from"]["trial"] == "best"
