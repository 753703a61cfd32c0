"""Plugin discovery: entry points (as a third-party package), --plugins-dir, faults."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from sitframe import hookimpl
from sitframe.contract.pluginmanager import Registry, get_plugin_manager, register
from sitframe.errors import InputError, PluginError

BUILTIN_COMPONENTS = {
    "sensor": {"pioneer-sonar", "laser"},
    "interpreter": {"fcm"},
    "reward": {"obstacle-avoidance", "speed"},
    "behaviour": {"fuzzy-q"},
    "arbiter": {"single"},
}


def test_builtins_come_through_entry_points():
    pm = get_plugin_manager(autoload=True)
    reg = Registry.collect(pm)
    for kind, names in BUILTIN_COMPONENTS.items():
        assert names <= set(reg.names(kind)), kind
    info = pm.sitframe_info["fuzzy-q"]
    assert info.origin == "entry point"
    assert info.distribution == "sitframe"


def test_autoload_switch(monkeypatch):
    monkeypatch.setenv("SITFRAME_DISABLE_PLUGIN_AUTOLOAD", "1")
    reg = Registry.collect(get_plugin_manager())
    assert reg.names("behaviour") == []


def _fake_distribution(tmp_path: Path, monkeypatch, module_src: str) -> None:
    """Install a third-party package the way pip would: module + dist-info entry point."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "thirdparty_sitframe.py").write_text(textwrap.dedent(module_src))
    dist = site / "thirdparty_sitframe-1.2.3.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: thirdparty-sitframe\n"
                                   "Version: 1.2.3\n")
    (dist / "entry_points.txt").write_text("[sitframe]\nthirdparty = thirdparty_sitframe\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.delitem(sys.modules, "thirdparty_sitframe", raising=False)


THIRD_PARTY = """
from sitframe import hookimpl

class Cautious:
    name = "cautious"
    def __init__(self, *, margin=0.5):
        self.margin = margin
    def __call__(self, tr):
        return -30.0 if tr.collided else 1.0

@hookimpl
def sitframe_rewards():
    return [Cautious]
"""


def test_third_party_entry_point(tmp_path, monkeypatch):
    _fake_distribution(tmp_path, monkeypatch, THIRD_PARTY)
    pm = get_plugin_manager(autoload=True)
    reg = Registry.collect(pm)
    assert "cautious" in reg.names("reward")
    assert "obstacle-avoidance" in reg.names("reward")
    info = pm.sitframe_info["thirdparty"]
    assert (info.distribution, info.version) == ("thirdparty-sitframe", "1.2.3")
    reward = reg.create("reward", "cautious", {"margin": 0.3})
    assert reward.margin == 0.3


def test_plugins_dir(tmp_path):
    (tmp_path / "myreward.py").write_text(THIRD_PARTY)
    pm = get_plugin_manager(autoload=False, plugins_dirs=[tmp_path])
    reg = Registry.collect(pm)
    assert reg.names("reward") == ["cautious"]
    assert pm.sitframe_info["myreward"].file == str(tmp_path / "myreward.py")


def test_a_plugins_dir_named_twice_loads_once(tmp_path, monkeypatch):
    # --plugins-dir plug and [plugins] dirs = ["plug"]: was "reward name 'cautious' is
    # registered by two plugins: myreward (...) and dir:myreward (...)"
    (tmp_path / "myreward.py").write_text(THIRD_PARTY)
    monkeypatch.chdir(tmp_path)
    pm = get_plugin_manager(autoload=False, plugins_dirs=[tmp_path, "."])
    assert Registry.collect(pm).names("reward") == ["cautious"]


def test_plugins_dir_syntax_error_names_file_and_line(tmp_path):
    (tmp_path / "broken.py").write_text("x = 1\ndef oops(:\n")
    with pytest.raises(PluginError, match=r"broken\.py:2: syntax error"):
        get_plugin_manager(autoload=False, plugins_dirs=[tmp_path])


def test_plugins_dir_import_error_names_file(tmp_path):
    (tmp_path / "bad.py").write_text("import not_a_module_xyz\n")
    with pytest.raises(PluginError, match=r"bad\.py:1: failed to import: ModuleNotFoundError"):
        get_plugin_manager(autoload=False, plugins_dirs=[tmp_path])


class _A:
    name = "dup"

    def __call__(self, tr):
        return 0.0


class PluginOne:
    @hookimpl
    def sitframe_rewards(self):
        return [_A]


class PluginTwo:
    @hookimpl
    def sitframe_rewards(self):
        return [_A]


def test_duplicate_names_name_both_plugins():
    pm = get_plugin_manager(autoload=False)
    register(pm, PluginOne(), "one")
    register(pm, PluginTwo(), "two")
    with pytest.raises(PluginError, match=r"reward name 'dup' is registered by two plugins: "
                                          r"one \(registered\) and two \(registered\)"):
        Registry.collect(pm)


class Raises:
    @hookimpl
    def sitframe_behaviours(self):
        raise RuntimeError("boom")


class WrongType:
    @hookimpl
    def sitframe_arbiters(self):
        return {"not": "a list"}


class Nameless:
    @hookimpl
    def sitframe_sensors(self):
        return [object]


@pytest.mark.parametrize(
    ("plugin", "pattern"),
    [
        (Raises(), r"plugin bad \(registered\) raised in hook sitframe_behaviours: "
                   r"RuntimeError: boom"),
        (WrongType(), r"plugin bad \(registered\): hook sitframe_arbiters must return a list"),
        (Nameless(), r"plugin bad \(registered\): hook sitframe_sensors returned .* not a "
                     r"callable with a non-empty string attribute 'name'"),
    ],
)
def test_plugin_faults_name_the_plugin_and_hook(plugin, pattern):
    pm = get_plugin_manager(autoload=False)
    register(pm, plugin, "bad")
    with pytest.raises(PluginError, match=pattern):
        Registry.collect(pm)


def test_unknown_component_lists_available():
    reg = Registry.collect(get_plugin_manager(autoload=True))
    with pytest.raises(InputError, match=r"unknown reward 'obstacle-avoidence' \(did you mean "
                                         r"'obstacle-avoidance'\?\); available: "):
        reg.get("reward", "obstacle-avoidence", key="behaviours.avoid.reward")


def test_unknown_parameter_suggests_closest():
    reg = Registry.collect(get_plugin_manager(autoload=True))
    with pytest.raises(InputError, match=r"behaviours.avoid.alpah: unknown parameter 'alpah' "
                                         r"\(did you mean 'alpha'\?\)"):
        reg.create("behaviour", "fuzzy-q", {"alpah": 0.3}, key="behaviours.avoid")


def test_bad_parameter_value_is_located():
    reg = Registry.collect(get_plugin_manager(autoload=True))
    with pytest.raises(InputError, match=r"cfg.toml: behaviours.avoid.alpha: expected a number "
                                         r"in \(0.0, 1.0\], got 1.5"):
        reg.create("behaviour", "fuzzy-q", {"alpha": 1.5}, file="cfg.toml",
                   key="behaviours.avoid")
