"""The documentation's examples are run, and its generated reference misses nothing.

The examples themselves run as tests collected by Sybil (the root ``conftest.py``; the
rules in ``tests/doc_examples.py``). Here: the share of code blocks that run (at least
90 %, the others listed with their reasons), and the generated reference pages
(``docs/hooks/generate.py``) against the code they are made from.
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import re

import pytest
from doc_examples import CODE, NOT_CODE, ROOT, blocks, pages

from sitframe.cli import build_parser
from sitframe.contract import config as C


def _generate():
    spec = importlib.util.spec_from_file_location("docs_generate",
                                                  ROOT / "docs" / "hooks" / "generate.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module._importable()
    return module


@pytest.fixture(scope="module")
def generate():
    return _generate()


def _all_blocks():
    return [b for p in pages() for b in blocks(p.read_text("utf-8"),
                                               p.relative_to(ROOT).as_posix())]


def test_at_least_90_percent_of_the_code_blocks_run(capsys: pytest.CaptureFixture[str]) -> None:
    bs = _all_blocks()
    unknown = [f"{b.where}: ```{b.lang}" for b in bs if b.lang not in CODE + NOT_CODE]
    assert not unknown, f"blocks of a language the runner does not know: {unknown}"
    code = [b for b in bs if b.is_code]
    skipped = [b for b in code if b.skip is not None]
    assert all(b.skip.strip() for b in skipped), "a skip without a reason"
    ran = len(code) - len(skipped)
    listing = "\n".join(f"  {b.where} ({b.lang}): {b.skip}" for b in skipped)
    with capsys.disabled():
        print(f"\ndocs: {ran} of {len(code)} code blocks run ({ran / len(code):.0%}); "
              f"left out:\n{listing}")
    assert len(code) >= 60  # the pages are found
    assert ran / len(code) >= 0.9, f"only {ran} of {len(code)} code blocks run:\n{listing}"


def test_the_readme_keeps_its_two_lines_alone_in_bash_blocks() -> None:
    """``.ci/run`` greps these two lines from README.md and runs them verbatim."""
    readme = [b for b in _all_blocks() if b.page == "README.md"]
    for pattern in (r"^python3 -m venv .* && sitframe run ", r"^python3 -m venv .* && pytest"):
        (block,) = [b for b in readme if re.search(pattern, b.text, re.MULTILINE)]
        assert block.lang == "bash" and len(block.text.strip().splitlines()) == 1


def test_the_readme_is_short() -> None:
    assert len((ROOT / "README.md").read_text("utf-8").splitlines()) <= 200


def _options(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    out = {"": parser}
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, sub in a.choices.items():
                out |= {f"{name} {k}".strip(): v for k, v in _options(sub).items()}
    return out


def test_the_cli_reference_has_every_command_and_option(generate) -> None:
    text = generate.cli_reference()
    for name, parser in _options(build_parser()).items():
        if name:
            assert f"`sitframe {name}`" in text, name
        for action in parser._actions:
            for option in action.option_strings:
                if option not in ("-h", "--help"):
                    assert f"`{option}" in text, f"sitframe {name} {option}"


def test_the_cli_reference_lists_every_environment_variable(generate) -> None:
    from sitframe.params import ENVIRONMENT

    rows = generate.environment_reference().splitlines()
    assert [row.split("`")[1] for row in rows] == list(ENVIRONMENT)


def test_the_config_reference_has_every_key(generate) -> None:
    text = generate.config_reference()
    for section, keys in C.DEFAULTS.items():
        for key in keys:
            assert re.search(rf"## `\[{section}\]`.*?\| `{key}` \|", text, re.S), \
                f"{section}.{key}"
    from sitframe.sim.robot import RobotParams

    for name in inspect.signature(RobotParams).parameters:
        assert f"| `{name}` |" in text, f"robot.{name}"
    for table in (C.POLICY_FROM, C.SELECTION):
        for k in table.keys:
            assert f"| `{k.name}` |" in text


def test_the_config_reference_lists_the_plugins_tables(generate) -> None:
    """The built-in protocols' tables ([evaluate], [goal]) are declared by their plugins and
    listed, key by key, under the plugins' tables of the config reference."""
    from sitframe.plugins.frozen_evaluation import EVALUATE
    from sitframe.plugins.goal_episodes import GOAL

    text = generate.config_reference().split("## Tables the plugins declare", 1)[1]
    for table in (EVALUATE, GOAL):
        section = text.split(f"### `[{table.name}]`", 1)[1].split("\n### ", 1)[0]
        for key in table.keys:
            assert f"| `{key.name}` |" in section, (table.name, key.name)


def test_the_components_reference_has_every_builtin_and_parameter(generate) -> None:
    from sitframe.params import accepted_params

    text = generate.components_reference()
    registry = generate._registry()
    for kind, entries in registry.entries.items():
        for name, entry in entries.items():
            section = text.split(f"### `{name}`", 1)[1].split("\n### ", 1)[0]
            for param in accepted_params(entry.factory)[0]:
                assert f"| `{param}` |" in section, f"{kind} {name}: {param}"


def test_the_layers_picture_is_drawn_from_the_code(generate) -> None:
    text = generate.layers_diagram()
    svg = text.split("\n", 1)[0]
    assert svg.startswith("<svg") and svg.endswith("</svg>")  # (one line: Markdown keeps it)
    for name in generate.SUBPACKAGES:
        assert f">{name}</text>" in svg
    assert svg.count("<path d=") >= len(generate.SUBPACKAGES)  # an arrow into each but cli
    contracts = generate.import_contracts()
    assert len(contracts) >= 5
    for c in contracts:
        assert c["name"] in text


def test_the_readme_headline_table_is_the_published_one() -> None:
    """README.md's results table is the one the script wrote (docs/results/tables/headline.md),
    links pointing into docs/: never edited by hand."""
    import sys

    sys.path.insert(0, str(ROOT / "benchmarks" / "report"))
    from regenerate import readme_table

    published = (ROOT / "docs" / "results" / "tables" / "headline.md").read_text("utf-8")
    table = "\n".join(line for line in published.splitlines()
                      if not line.startswith("*Made by")).strip()  # (or the pending line)
    readme = (ROOT / "README.md").read_text("utf-8")
    block = readme.split("<!-- headline:start -->\n", 1)[1].split("<!-- headline:end -->")[0]
    assert block.strip() == readme_table(table).strip()


def test_the_references_sphinx_roles_read_as_plain_code():
    """A docstring's ``:func:`~sitframe.scratch.limit``` reads ``limit`` in the reference, not
    ``:func:limit``; a role without ``~`` keeps its whole name; other text is untouched."""
    plain = _generate().plain_roles
    assert plain("sets :func:<code>~sitframe.scratch.limit</code> (default)") == \
        "sets <code>limit</code> (default)"
    assert plain("a :class:<code>numpy.memmap</code> and :meth:<code>Foo.bar</code>") == \
        "a <code>numpy.memmap</code> and <code>Foo.bar</code>"
    assert plain("ratio: 3:<code>x</code>") == "ratio: 3:<code>x</code>"
