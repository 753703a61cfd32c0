"""The generated parts of the documentation site, made from the code as the site builds.

A MkDocs hooks module (``hooks:`` in mkdocs.yml). A page asks for a generated part with a
marker line, ``<!-- generated: NAME [ARG] -->``, which :func:`on_page_markdown` replaces
by what :data:`GENERATORS` ``[NAME]`` returns for it:

``cli``
    Every command of ``sitframe``, grouped as ``sitframe --help`` groups them, with its
    usage, options (default and help) and example: from :func:`sitframe.cli.build_parser`.
``environment``
    The environment variables sitframe reads, their values, defaults and meanings: from
    :data:`sitframe.params.ENVIRONMENT`, the declarations that check them.
``config``
    Every config key with its type, default, unit and range: from the typed config's
    declarations (:mod:`sitframe.contract.config`), the ones validation uses.
``components``
    Every built-in component with its parameters (default from the signature, type, unit
    and range where the component declares them): from the plugin registry.
``layers``
    The picture of the layers: import-linter's contracts in pyproject.toml for the order,
    grimp's import graph for the arrows (one per import between two subpackages that no
    longer chain implies), as an SVG drawn here; then the contracts, which ``lint-imports``
    keeps in CI.
``subpackages``
    One row per subpackage: its job and what it may import, from its ``__init__``
    docstring.
``face``
    The public face, ``from sitframe import ...``: every name with its documentation.
``api PACKAGE``
    A subpackage's modules, documented from their docstrings (mkdocstrings directives).

The functions are plain functions of no MkDocs state, so the tests call them too
(``tests/test_doc_examples.py``): no page can go stale, and none can miss a command, an
option or a key.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import re
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]


def _importable() -> None:
    """The checkout first on ``sys.path``: ``plugins`` (the built-ins' source) and sitframe
    import from it. (MkDocs restores ``sys.path`` after loading a hooks module, so this is
    done as each part is made.)"""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))

MARKER = re.compile(r"^<!-- generated: (?P<name>[\w-]+)(?: (?P<arg>[\w.-]+))? -->$",
                    re.MULTILINE)

#: The subpackages of sitframe, top layer first (the order of the API pages).
SUBPACKAGES = ("cli", "gym", "analysis", "runs", "logs", "contract", "learning",
               "situations", "sim")


# -- small helpers -----------------------------------------------------------------------

_ROLE = re.compile(r":(?:mod|func|class|data|meth|attr|exc):`(~?)([\w.]+)`")


def rst_to_md(text: str) -> str:
    """Sphinx roles and double backticks of a docstring as Markdown code."""
    text = _ROLE.sub(lambda m: f"`{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}`",
                     text)
    return text.replace("``", "`")


def cell(text: Any) -> str:
    """``text`` fit for one Markdown table cell."""
    text = " ".join(str(text).split()).replace("|", "\\|")
    return text.replace("<", "&lt;").replace(">", "&gt;")


def docstring_sections(doc: str) -> tuple[str, dict[str, str]]:
    """The summary line of a subpackage docstring and its headed paragraphs."""
    lines = (doc or "").strip().splitlines()
    summary = lines[0] if lines else ""
    sections: dict[str, list[str]] = {}
    current = None
    for line in lines[1:]:
        if line and not line.startswith(" "):
            current = line.strip()
            sections[current] = []
        elif current is not None:
            sections[current].append(line.strip())
    return summary, {k: " ".join(v).strip() for k, v in sections.items()}


# -- the command line --------------------------------------------------------------------


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _help_of(parser: argparse.ArgumentParser) -> dict[str, str]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def _option_rows(parser: argparse.ArgumentParser) -> list[str]:
    rows = []
    for a in parser._actions:
        if isinstance(a, argparse._HelpAction | argparse._SubParsersAction):
            continue
        takes_value = a.nargs != 0
        metavar = a.metavar if isinstance(a.metavar, str) else a.dest.upper()
        if a.option_strings:
            name = ", ".join(f"`{o} {metavar}`" if takes_value else f"`{o}`"
                             for o in a.option_strings)
        else:
            name = f"`{a.metavar or a.dest}`"
        shown = a.default is not None and a.default is not False and a.default != [] \
            and a.default is not argparse.SUPPRESS and not a.required and takes_value
        default = f"`{a.default}`" if shown else ""
        if a.choices is not None:
            extra = "one of " + ", ".join(f"`{c}`" for c in a.choices)
            default = f"{default} ({extra})" if default else extra
        help_text = (a.help or "") % {"default": a.default} if a.help else ""
        rows.append(f"| {name} | {cell(help_text)} | {cell(default)} |")
    return rows


def _command_section(name: str, parser: argparse.ArgumentParser, help_text: str,
                     level: str = "###") -> list[str]:
    out = [f"{level} `sitframe {name}`", "", cell(help_text) + ("." if help_text else ""), ""]
    out += ["```text", parser.format_usage().strip(), "```", ""]
    if parser.description:
        out += [rst_to_md(parser.description.strip()), ""]
    rows = _option_rows(parser)
    if rows:
        out += ["| argument | meaning | default |", "|---|---|---|", *rows, ""]
    subs = _subcommands(parser)
    helps = _help_of(parser)
    for sub, sub_parser in subs.items():
        out += _command_section(f"{name} {sub}", sub_parser, helps.get(sub, ""), level + "#")
    if parser.epilog and not subs:
        out += ["Example:", "", "```text", parser.epilog.strip(), "```", ""]
    return out


def cli_reference(_arg: str | None = None) -> str:
    """Every command and option of ``sitframe``, grouped as ``sitframe --help`` groups them."""
    from sitframe.cli import build_parser

    parser = build_parser()
    groups = getattr(sys.modules[build_parser.__module__], "COMMAND_GROUPS", None) \
        or {"commands": list(_subcommands(parser))}
    subs, helps = _subcommands(parser), _help_of(parser)
    out = ["```text", parser.format_help().strip(), "```", "",
           "## Options of every command", "",
           "| argument | meaning | default |", "|---|---|---|", *_option_rows(parser), ""]
    for group, names in groups.items():
        out += [f"## {group.capitalize()}", ""]
        for name in names:
            out += _command_section(name, subs[name], helps.get(name, ""))
    return "\n".join(out)


def environment_reference(_arg: str | None = None) -> str:
    """The environment variables sitframe reads (:data:`sitframe.params.ENVIRONMENT`)."""
    from sitframe.params import ENVIRONMENT

    rows = []
    for k in ENVIRONMENT.values():
        values = {"text": "any value", "path": "a folder"}.get(k.kind) or (
            f"an integer in {k.range_text}" if k.kind == "integer"
            else " or ".join([", ".join(f"`{c}`" for c in k.choices[:-1]), f"`{k.choices[-1]}`"]))
        default = f", default `{k.default}`" if k.default != "" else ""
        rows.append(f"- **`{k.name}`** ({values}{default}): {k.doc}")
    return "\n".join(rows) + "\n"


# -- config keys and components ----------------------------------------------------------


def param_docs(obj: Any) -> dict[str, str]:
    """``name -> description`` from the numpy ``Parameters`` / ``Attributes`` sections of
    ``obj``'s docstring (``a, b`` entries describe both)."""
    import inspect

    doc = inspect.getdoc(obj) or ""
    out: dict[str, str] = {}
    lines = doc.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].strip() in ("Parameters", "Attributes") and i + 1 < len(lines) \
                and set(lines[i + 1].strip()) == {"-"}:
            i += 2
            names: list[str] = []
            while i < len(lines) and (not lines[i].strip() or lines[i].startswith(" ")
                                      or not set(lines[i + 1:i + 2] and lines[i + 1].strip())
                                      == {"-"}):
                line = lines[i]
                if line.strip() and not line.startswith(" "):
                    names = [n.strip() for n in line.split(":")[0].split(",")]
                    out.update(dict.fromkeys(names, ""))
                elif line.strip() and names:
                    for n in names:
                        out[n] = (out[n] + " " + line.strip()).strip()
                elif not line.strip() and names and i + 1 < len(lines) \
                        and lines[i + 1].strip() and not lines[i + 1].startswith(" "):
                    pass
                i += 1
                if i < len(lines) and lines[i].strip() and not lines[i].startswith(" ") \
                        and i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"}:
                    break
        else:
            i += 1
    return {k: rst_to_md(v) for k, v in out.items()}


def _default_text(key: Any) -> str:
    from sitframe.params import ABSENT, REQUIRED

    if key.default is REQUIRED:
        return "required"
    if key.default is ABSENT or key.default is None:
        return ""
    value = key.default
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, list | tuple):
        return "`[" + ", ".join(f'"{v}"' if isinstance(v, str) else f"{v:g}"
                                if isinstance(v, float) else str(v) for v in value) + "]`"
    if isinstance(value, float):
        return f"`{value:g}`"
    return f"`{value}`"


def key_rows(keys: Any, docs: dict[str, str] | None = None) -> list[str]:
    """Markdown rows (key, type, default, unit, range, meaning) of declared keys."""
    docs = docs or {}
    out = ["| key | type | default | unit | range | meaning |", "|---|---|---|---|---|---|"]
    for k in keys:
        meaning = k.doc or docs.get(k.name, "")
        out.append(f"| `{k.name}` | {cell(k.type_text)} | {cell(_default_text(k))} | "
                   f"{cell(k.unit)} | {cell(k.range_text)} | {cell(meaning)} |")
    return out


def _registry() -> Any:
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager

    return Registry.collect(get_plugin_manager(), strict=False)


def config_reference(_arg: str | None = None) -> str:
    """Every table and key of a run config: type, default, unit, range and meaning."""
    from sitframe.contract import config as C
    from sitframe.contract.tables import plugin_tables, tables_reference
    from sitframe.params import declared_params
    from sitframe.sim.robot import RobotParams

    tables = list(C.TABLES)
    at = tables.index(C.BEHAVIOUR) + 1
    tables[at:at] = [C.POLICY_FROM, C.SELECTION]
    tables.insert(tables.index(C.ARBITER) + 1, C.SPACE)
    tables.insert(tables.index(C.PLUGINS), C.PREREQUISITES)
    out = []
    for t in tables:
        out += [f"## `[{t.name}]`", "", rst_to_md(t.doc), ""]
        keys: list[Any] = list(t.keys)
        docs: dict[str, str] = {}
        if t is C.ROBOT:
            keys, docs = declared_params(RobotParams), param_docs(RobotParams)
        if keys:
            out += [*key_rows(keys, docs), ""]
        if t.free and t not in (C.ROBOT, C.PREREQUISITES):
            out += ["Besides these keys, the component's own parameters: "
                    "[components](components.md).", ""]
    registry = _registry()
    out += ["## Tables the plugins declare", "",
            "A plugin's component may declare a table of its own (`config_table`, see the "
            "plugin guide); these are the tables the plugins installed when this page was "
            "built declare (`sitframe plugins --tables` prints them for yours).", "",
            tables_reference(plugin_tables(registry), registry)]
    return "\n".join(out)


def generator_reference(_arg: str | None = None) -> str:
    """The room generator's parameters (a world file's ``[generator]`` table)."""
    from sitframe.sim.roomgen import GENERATOR

    return "\n".join(key_rows(GENERATOR.keys))


def components_reference(_arg: str | None = None) -> str:
    """Every built-in component by kind, with its parameters."""
    import inspect

    from sitframe.params import declared_params

    registry = _registry()
    out = []
    for kind, entries in registry.entries.items():
        out += [f"## {kind.capitalize()}s", ""]
        for name, entry in sorted(entries.items()):
            factory = entry.factory
            summary = (inspect.getdoc(factory) or "").split("\n\n")[0]
            plugin = registry.describe_plugin(entry.plugin)
            out += [f"### `{name}`", "", f"{cell(rst_to_md(summary))} (plugin {plugin};"
                    f" `{factory.__module__}.{factory.__qualname__}`)", ""]
            keys = declared_params(factory)
            if getattr(factory, "table", None):
                out += [f"Its parameters are the config table `[{factory.table}]`.", ""]
            if keys:
                out += [*key_rows(keys, param_docs(factory)), ""]
            else:
                out += ["No parameters.", ""]
    return "\n".join(out)


# -- the layers --------------------------------------------------------------------------


def import_contracts() -> list[dict[str, Any]]:
    """import-linter's contracts, as pyproject.toml declares them."""
    data = tomllib.loads((ROOT / "pyproject.toml").read_text("utf-8"))
    return list(data.get("tool", {}).get("importlinter", {}).get("contracts", []))


def _package_edges(packages: list[str]) -> set[tuple[str, str]]:
    import grimp

    graph = grimp.build_graph("sitframe", "plugins", cache_dir=None)
    return {(a, b) for a in packages for b in packages if a != b and
            graph.direct_import_exists(importer=a, imported=b, as_packages=True)}


def _reduce(edges: set[tuple[str, str]]) -> set[tuple[str, str]]:
    """The edges no longer path implies (a transitive reduction of an acyclic graph)."""
    succ: dict[str, set[str]] = {}
    for a, b in edges:
        succ.setdefault(a, set()).add(b)

    def reach(a: str, skip: tuple[str, str]) -> set[str]:
        seen, todo = set(), [n for n in succ.get(a, ()) if (a, n) != skip]
        while todo:
            n = todo.pop()
            if n not in seen:
                seen.add(n)
                todo += succ.get(n, ())
        return seen

    return {(a, b) for a, b in edges if b not in reach(a, (a, b))}


def layers_diagram(_arg: str | None = None) -> str:
    """The layers as an SVG picture drawn here (no script or network needed to see it), and
    the contracts that keep them."""
    contracts = import_contracts()
    layered = next(c for c in contracts if c.get("type") == "layers")
    rows = [[m.strip() for m in layer.split("|")] for layer in layered["layers"]]
    import sitframe  # the ground floor: sitframe's own modules outside every subpackage

    ground = [f"sitframe.{i.name}" for i in pkgutil.iter_modules(sitframe.__path__[:1])
              if not i.ispkg and not i.name.startswith("_")]
    edges = _reduce(_package_edges([m for row in rows for m in row] + ground))

    def label(m: str) -> tuple[str, str]:
        mod = importlib.import_module(m)
        count = sum(1 for _ in pkgutil.iter_modules(getattr(mod, "__path__", [])))
        return m.removeprefix("sitframe."), f"{count} modules" if hasattr(mod, "__path__") \
            else "module"

    boxes = [[("plugins/", "the built-ins")], [("sitframe", "the public face")],
             *[[label(m) for m in row] for row in rows], [label(m) for m in ground]]
    svg = _layers_svg(boxes, [("plugins/", "sitframe")] + [
        (a.removeprefix("sitframe."), b.removeprefix("sitframe.")) for a, b in sorted(edges)])
    out = [svg, "", "*The rows are import-linter's layers contract, top to bottom, above the "
           "ground floor; a plugin imports only the public face. An arrow is an import from "
           "one subpackage into another that no chain of other arrows already implies. Drawn "
           "from the code as this site builds.*", "",
           "The contracts, kept by `lint-imports` in CI:", ""]
    out += [f"- **{cell(c['name'])}** ({c['type']})" for c in contracts]
    return "\n".join(out)


def _layers_svg(rows: list[list[tuple[str, str]]], arrows: list[tuple[str, str]]) -> str:
    """An SVG of ``rows`` of boxes ``(name, what)``, top to bottom, and ``arrows`` (importer,
    imported) between them; an arrow that passes rows goes round them, on its side. One
    line, no blank line: Markdown keeps it as HTML. Colours follow the site's theme."""
    width, row_h, box_h, gap = 640, 78, 42, 22
    at: dict[str, tuple[float, int, float]] = {}  # name -> (left, row, width)
    left, right = [0.0] * len(rows), [0.0] * len(rows)  # each row's edges
    for r, row in enumerate(rows):
        ws = [8.0 * max(len(n), len(w)) + 28 for n, w in row]
        x = left[r] = (width - sum(ws) - gap * (len(ws) - 1)) / 2
        for (name, _w), w in zip(row, ws, strict=True):
            at[name] = (x, r, w)
            x += w + gap
        right[r] = x - gap
    parts, rounds = [], 0
    for a, b in arrows:
        (xa, ra, wa), (xb, rb, wb) = at[a], at[b]
        ya, yb = 16 + ra * row_h, 16 + rb * row_h
        mid_a, mid_b = ya + box_h / 2, yb + box_h / 2
        if rb == ra:  # side by side (the ground floor)
            x1, x2 = (xa, xb + wb + 3) if xb < xa else (xa + wa, xb - 3)
            d = f"M{x1:.0f},{mid_a:.0f} L{x2:.0f},{mid_b:.0f}"
        elif rb - ra > 1:  # round the rows between, on the importer's side of the picture
            if xa + wa / 2 < width / 2:
                side, x1, x2 = min(left[ra + 1:rb]) - 28 - 14 * rounds, xa, xb - 3
            else:
                side, x1, x2 = max(right[ra + 1:rb]) + 28 + 14 * rounds, xa + wa, xb + wb + 3
            rounds += 1
            d = f"M{x1:.0f},{mid_a:.0f} C{side:.0f},{mid_a:.0f} {side:.0f},{mid_b:.0f} " \
                f"{x2:.0f},{mid_b:.0f}"
        else:
            d = f"M{xa + wa / 2:.0f},{ya + box_h:.0f} L{xb + wb / 2:.0f},{yb - 3:.0f}"
        parts.append(f'<path d="{d}" fill="none" stroke="currentColor" stroke-opacity="0.55" '
                     'stroke-width="1.4" marker-end="url(#layers-arrow)"/>')
    for name, what in (b for row in rows for b in row):
        x, r, w = at[name]
        y = 16 + r * row_h
        parts.append(f'<rect x="{x:.0f}" y="{y:.0f}" width="{w:.0f}" height="{box_h}" rx="6" '
                     'style="fill:var(--md-code-bg-color,#f5f5f5);'
                     'stroke:var(--md-primary-fg-color,#009485)" stroke-width="1.5"/>'
                     f'<text x="{x + w / 2:.0f}" y="{y + 17:.0f}" text-anchor="middle" '
                     f'font-weight="bold" font-size="13" fill="currentColor">{name}</text>'
                     f'<text x="{x + w / 2:.0f}" y="{y + 33:.0f}" text-anchor="middle" '
                     f'font-size="11" fill="currentColor" fill-opacity="0.7">{what}</text>')
    height = 16 + len(rows) * row_h - (row_h - box_h) + 16
    return (f'<svg class="layers" viewBox="0 0 {width} {height}" width="{width}" '
            f'role="img" aria-label="The layers of sitframe, top to bottom" '
            'style="max-width:100%;height:auto" xmlns="http://www.w3.org/2000/svg">'
            '<defs><marker id="layers-arrow" viewBox="0 0 10 10" refX="9" refY="5" '
            'markerWidth="7" markerHeight="7" orient="auto-start-reverse">'
            '<path d="M0,0 L10,5 L0,10 z" fill="currentColor" fill-opacity="0.7"/></marker>'
            f'</defs>{"".join(parts)}</svg>')


def subpackages_table(_arg: str | None = None) -> str:
    """One row per subpackage: its job and what it may import (from its docstring)."""
    out = ["| subpackage | its job | what it may import |", "|---|---|---|"]
    for name in SUBPACKAGES:
        summary, sections = docstring_sections(importlib.import_module(f"sitframe.{name}")
                                               .__doc__ or "")
        out.append(f"| [`sitframe.{name}`](../reference/api/{name}.md) | "
                   f"{cell(rst_to_md(summary))} | "
                   f"{cell(rst_to_md(sections.get('What it may import', '')))} |")
    return "\n".join(out)


# -- the Python API ----------------------------------------------------------------------


def face_page(_arg: str | None = None) -> str:
    """The public face: every name ``from sitframe import ...`` serves, with a link to its
    documentation where it is defined (each subpackage's page)."""
    import sitframe

    rows = []
    for name in sitframe._PUBLIC:
        home = getattr(getattr(sitframe, name), "__module__", None) or \
            f"sitframe.{sitframe._PUBLIC[name]}"
        page = home.split(".")[1] if home.count(".") > 1 else "ground"
        obj = getattr(sitframe, name)  # an alias (ConfigKey) links to its own name; a constant
        anchor = f"{home}.{obj.__name__}" if isinstance(obj, type) or callable(obj) else home
        summary = (getattr(getattr(sitframe, name), "__doc__", None) or "").strip()
        summary = summary.split("\n\n")[0] if summary and callable(getattr(sitframe, name)) \
            else ""
        rows.append(f"| [`{name}`]({page}.md#{anchor}) | `{home}` | "
                    f"{cell(rst_to_md(summary))} |")
    out = ["| name | defined in | what it is |", "|---|---|---|", *rows, "",
           "Modules used as namespaces: "
           + ", ".join(f"`sitframe.{k}` (`sitframe.{v}`)" for k, v in sitframe._MODULES.items())
           + ". `sitframe.hookimpl` is the pluggy marker of a hook implementation "
           "(`@hookimpl def sitframe_rewards(): ...`).", "",
           "::: sitframe", "    options:", "      members: false",
           "      show_root_heading: false", ""]
    return "\n".join(out)


def api_page(package: str | None) -> str:
    """A subpackage's modules, each documented from its docstrings."""
    assert package, "api needs a package: <!-- generated: api sitframe.sim -->"
    pkg = importlib.import_module(package)
    out = [f"::: {package}", "    options:", "      members: false",
           "      show_root_heading: false", ""]
    for info in pkgutil.iter_modules(pkg.__path__):
        if info.name.startswith("_") or info.name == "__main__":
            continue
        out += [f"::: {package}.{info.name}", "    options:", "      heading_level: 2", ""]
    return "\n".join(out)


GENERATORS: dict[str, Callable[[str | None], str]] = {
    "cli": cli_reference,
    "environment": environment_reference,
    "config": config_reference,
    "components": components_reference,
    "generator": generator_reference,
    "layers": layers_diagram,
    "subpackages": subpackages_table,
    "face": face_page,
    "api": api_page,
}


def render(markdown: str) -> str:
    """``markdown`` with every marker replaced by its generated part."""
    _importable()
    return MARKER.sub(lambda m: GENERATORS[m.group("name")](m.group("arg")), markdown)


def on_page_markdown(markdown: str, **_kw: Any) -> str:
    """MkDocs hook: the page's markers replaced."""
    return render(markdown)


#: A Sphinx role as the API reference renders it from a docstring: ``:func:`~a.b.c```
#: becomes ``:func:<code>~a.b.c</code>``.
ROLE = re.compile(r":(?:func|class|meth|mod|data|attr|exc|obj):<code>(~?)([^<]*)</code>")


def plain_roles(html: str) -> str:
    """``html`` with the docstrings' Sphinx roles shown as code alone (``~`` shortening a
    dotted name to its last part, as Sphinx does)."""
    return ROLE.sub(lambda m: f"<code>{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}"
                              "</code>", html)


def on_page_content(html: str, **_kw: Any) -> str:
    """MkDocs hook: the reference's Sphinx roles shown as plain code (:func:`plain_roles`)."""
    return plain_roles(html)
