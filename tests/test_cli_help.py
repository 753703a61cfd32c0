"""``sitframe --help`` fits one screen, grouped; every command's help ends with an example
that is a valid command line."""

from __future__ import annotations

import argparse
import shlex

import pytest

from sitframe.cli import build_parser
from sitframe.cli.app import COMMAND_GROUPS, EXAMPLES


def _help(parser: argparse.ArgumentParser, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    monkeypatch.setenv("COLUMNS", "80")  # argparse wraps to the terminal's width
    return parser.format_help().rstrip("\n").splitlines()


def _commands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """Every command and nested command (``world show``) by its path."""
    out: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out[name] = sub
                out |= {f"{name} {k}": v for k, v in _commands(sub).items()}
    return out


def test_top_level_help_fits_one_screen(monkeypatch: pytest.MonkeyPatch) -> None:
    lines = _help(build_parser(), monkeypatch)
    assert len(lines) <= 24, "\n".join(lines)
    assert max(len(line) for line in lines) <= 80, "\n".join(lines)


def test_top_level_help_lists_every_command_once_in_its_group(
        monkeypatch: pytest.MonkeyPatch) -> None:
    text = "\n".join(_help(build_parser(), monkeypatch))
    top = [c for c in _commands(build_parser()) if " " not in c]
    grouped = [c for names in COMMAND_GROUPS.values() for c in names]
    assert sorted(grouped) == sorted(top)  # every command in exactly one group
    positions = []
    for group, names in COMMAND_GROUPS.items():
        assert f"\n  {group}:\n" in text
        for name in names:
            (line,) = [ln for ln in text.splitlines() if ln.split()[:1] == [name]
                       and ln.startswith("    ")]
            positions.append(text.index(line))
    assert positions == sorted(positions)  # in the groups' order: run, analyse, inspect
    assert "positional arguments" not in text  # not listed a second time, ungrouped


@pytest.mark.parametrize("command", sorted(EXAMPLES))
def test_every_command_help_ends_with_a_valid_example(
        command: str, monkeypatch: pytest.MonkeyPatch) -> None:
    parser = _commands(build_parser())[command]
    lines = _help(parser, monkeypatch)
    assert lines[-2:] == ["example:", f"  {EXAMPLES[command]}"]
    argv = shlex.split(EXAMPLES[command])
    assert argv[0] == "sitframe"
    args = build_parser().parse_args(argv[1:])  # argparse exits 2 on an invalid one
    assert " ".join(filter(None, (args.command, getattr(args, "world_command", None)))) \
        .startswith(command.split()[0])


def test_every_command_has_an_example() -> None:
    assert set(_commands(build_parser())) == set(EXAMPLES)


def test_no_command_or_option_without_help() -> None:
    for name, parser in _commands(build_parser()).items():
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue
            assert action.help, f"sitframe {name}: {action.dest} has no help"


@pytest.mark.parametrize("module", ["sitframe", "sitframe.cli"])
def test_python_dash_m_runs_the_command_line(module: str) -> None:
    """``python -m sitframe`` is the ``sitframe`` command, as ``python -m sitframe.cli`` is
    (where the console script is not on the PATH)."""
    import subprocess
    import sys

    from sitframe import __version__

    res = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True,
                         text=True, check=False)
    assert res.returncode == 0 and __version__ in res.stdout, res.stderr
