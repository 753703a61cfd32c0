"""Config tables a plugin declares: their keys, checked, filled in and documented from one place.

A run config's tables beyond the core's (``[experiment]``, ``[robot]``, ``[sensor]``,
``[collect]``, ``[interpreter]``, ``[behaviours.*]``, ``[arbiter]``, ``[plugins]``,
``[prerequisites]``) belong to plugins. A component declares one with the class attribute
``config_table`` (a :class:`ConfigTable` of :class:`ConfigKey`\\ s); an evaluation protocol's
table holds its parameters (its keyword arguments, and ``worlds``, the worlds a batch of its
episodes runs in), e.g. the built-in ``frozen`` protocol's ``[evaluate]`` and
``goal-episodes``' ``[goal]``. A protocol that only names its table (the older class
attribute ``table = "..."``) shares that table if another plugin declares it, else gets a
declaration made from its signature (every keyword argument, checked by the protocol when
it is created, and ``worlds``).

The run config (:mod:`sitframe.contract.config`) then treats a declared table like its own:

* **accepted and checked**: an unknown key (with a did-you-mean), a value of the wrong type
  or out of range is one line naming the config file and ``<table>.<key>``;
* **filled in and logged**: a table that is given, or that a component of the run declares
  (or the protocol one of them names), gets its defaults and is written with the config
  into the log, like a core table; a table a run does not use is not added (so installing a
  plugin does not change the text, or hash, of a config that does not use it), except one
  declared ``always`` (the built-in ``[evaluate]`` and ``[goal]``, in every config's text
  since before plugins declared them);
* **documented**: :func:`tables_reference` lists every declared table and key (type,
  default, unit, range, meaning) of the plugins found, for the reference docs and
  ``sitframe plugins``.

Bad declarations are one line naming the plugin: a table named like a core table, two
plugins declaring one table differently, a protocol declaring a key it does not take.

A component other than a protocol reads its table's values, as validated, in
``bind(run)``: ``run.tables["<table>"]``.

A plugin declares with the same types the core's tables are declared with
(:class:`sitframe.params.Key` and :class:`~sitframe.params.Table`, exported as
``ConfigKey`` and ``ConfigTable``).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from collections.abc import Iterable, Mapping
from typing import Any

from sitframe import params as P
from sitframe.errors import InputError, PluginError, did_you_mean

__all__ = ["ABSENT", "CORE_TABLES", "REQUIRED", "ConfigKey", "ConfigTable", "PluginTables",
           "plugin_tables", "protocol_key", "tables_reference"]

#: The core's own tables (the config module checks them); a plugin may not declare these.
CORE_TABLES = ("experiment", "robot", "sensor", "collect", "interpreter", "behaviours",
               "arbiter", "plugins", "prerequisites")


#: A key of a plugin's table: :class:`sitframe.params.Key`, the core's own declaration (name,
#: kind, default, doc, unit, range, choices; :data:`REQUIRED` / :data:`ABSENT` defaults).
ConfigKey = P.Key
#: A plugin's table: :class:`sitframe.params.Table` (name, keys, doc, ``always``), the core's
#: own declaration, so one kind of declaration serves core and plugin tables alike.
ConfigTable = P.Table
REQUIRED, ABSENT, KINDS = P.REQUIRED, P.ABSENT, P.KINDS


def signature_table(name: str, factory: Any) -> ConfigTable:
    """The declaration of a protocol that names its table (``table = "..."``) but declares no
    keys: every keyword argument (kind ``"any"``: the protocol checks it when it is
    created), and ``worlds``."""
    try:
        params = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):
        params = []  # type: ignore[assignment]
    keys = [ConfigKey(p.name, "any", ABSENT) for p in params
            if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.name != "self"]
    if not any(k.name == "worlds" for k in keys):
        keys.append(ConfigKey("worlds", "names", ABSENT,
                              "the worlds a batch of the protocol's episodes runs in"))
    return ConfigTable(name, tuple(keys), (inspect.getdoc(factory) or "").split("\n\n")[0])


@dataclasses.dataclass
class PluginTables:
    """The tables the registered plugins declare, and who declares (and uses) each.

    Attributes
    ----------
    tables
        Table name -> its declaration.
    owners
        Table name -> ``(kind, component name, plugin)`` of each component declaring it.
    declared_by
        ``(kind, component name)`` -> the tables that component declares.
    protocol_of
        ``(kind, component name)`` -> the evaluation protocol the component names
        (its class attribute ``evaluation_protocol``).
    clashes
        Bad declarations found with ``strict=False`` (one line each).
    """

    tables: dict[str, ConfigTable] = dataclasses.field(default_factory=dict)
    owners: dict[str, list[tuple[str, str, str]]] = dataclasses.field(default_factory=dict)
    declared_by: dict[tuple[str, str], list[str]] = dataclasses.field(default_factory=dict)
    protocol_of: dict[tuple[str, str], str] = dataclasses.field(default_factory=dict)
    clashes: list[str] = dataclasses.field(default_factory=list)

    def used(self, cfg: Mapping[str, Any], default_protocol: str) -> list[str]:
        """The declared tables a config's components use: their own, and the table of the
        protocol they name (``default_protocol`` when none names one)."""
        comps = [("sensor", _component(cfg.get("sensor"))),
                 ("interpreter", _component(cfg.get("interpreter"))),
                 ("arbiter", _component(cfg.get("arbiter")))]
        for table in [cfg.get("arbiter"), *dict(cfg.get("behaviours") or {}).values()]:
            if isinstance(table, dict):
                if table is not cfg.get("arbiter"):
                    comps.append(("behaviour", _component(table)))
                if isinstance(table.get("reward"), str):
                    comps.append(("reward", table["reward"]))
        out: list[str] = []
        protocols = [p for c in comps if (p := self.protocol_of.get(c))]
        for proto in protocols or [default_protocol]:
            comps.append(("protocol", proto))
        for c in comps:
            out += self.declared_by.get(c, [])
        return list(dict.fromkeys(out))


def _component(table: Any) -> str:
    return str(table.get("component", "")) if isinstance(table, dict) else ""


def plugin_tables(registry: Any, *, strict: bool = True) -> PluginTables:
    """The tables the components of ``registry`` declare (module docstring).

    Raises
    ------
    PluginError
        (``strict``) A declaration that is not a :class:`ConfigTable`, a table named like a
        core table, one table declared differently by two components, a protocol declaring
        a key it does not take: one line naming the plugin and the table.
    """
    out = PluginTables()
    named: list[tuple[str, Any]] = []  # protocols that only name their table
    for kind, entries in registry.entries.items():
        for name, entry in entries.items():
            factory = entry.factory
            if isinstance(proto := getattr(factory, "evaluation_protocol", None), str):
                out.protocol_of[(kind, name)] = proto
            table = getattr(factory, "table", None) if kind == "protocol" else None
            if getattr(factory, "config_table", None) is None:
                if isinstance(table, str) and table:
                    named.append((table, entry))
                continue
            try:
                _add(out, _declaration(kind, name, factory, where=_where(registry, entry)),
                     kind, name, entry.plugin, registry)
            except PluginError as exc:
                if strict:
                    raise
                out.clashes.append(str(exc))
    for table, entry in named:  # another's declared table, or one made from its signature
        try:
            decl = out.tables.get(table) or _declaration(
                entry.kind, entry.name, entry.factory, signature_table(table, entry.factory),
                where=_where(registry, entry))
            _add(out, decl, entry.kind, entry.name, entry.plugin, registry)
        except PluginError as exc:
            if strict:
                raise
            out.clashes.append(str(exc))
    return out


def _where(registry: Any, entry: Any) -> str:
    return f"plugin {registry.describe_plugin(entry.plugin)}: {entry.kind} '{entry.name}'"


def _declaration(kind: str, name: str, factory: Any, decl: ConfigTable | None = None, *,
                 where: str = "") -> ConfigTable:
    """The table ``factory`` declares (``config_table``, or ``decl``), checked; ``where``
    names the plugin and component in the errors."""
    decl = getattr(factory, "config_table", None) if decl is None else decl
    table = getattr(factory, "table", None) if kind == "protocol" else None
    where = where or f"{kind} '{name}'"
    if not isinstance(decl, ConfigTable):
        raise PluginError(f"{where}: config_table is {type(decl).__name__} {decl!r}, expected "
                          "a sitframe.ConfigTable")
    if not isinstance(decl.name, str) or not decl.name or "." in decl.name:
        raise PluginError(f"{where}: config_table names the table {decl.name!r}, expected a "
                          "non-empty name without '.'")
    if decl.name in CORE_TABLES:
        raise PluginError(f"{where}: config_table declares [{decl.name}], which is the core's "
                          f"own table; expected another name (the core's: "
                          f"{', '.join(CORE_TABLES)})")
    names = [k.name for k in decl.keys if isinstance(k, ConfigKey)]
    if len(names) != len(decl.keys) or len(set(names)) != len(names):
        raise PluginError(f"{where}: config_table [{decl.name}] must hold ConfigKeys with "
                          f"different names, got {list(decl.keys)!r}")
    bad = [k.name for k in decl.keys if k.kind not in KINDS]
    if bad:
        raise PluginError(f"{where}: config_table [{decl.name}]: key {bad[0]!r} has kind "
                          f"{decl.key(bad[0]).kind!r}, expected one of {', '.join(KINDS)}")
    if kind == "protocol":
        if isinstance(table, str) and table != decl.name:
            raise PluginError(f"{where}: its table is '{table}' but its config_table declares "
                              f"[{decl.name}]; expected one name")
        accepted, var_kw = P.accepted_params(factory)
        extra = [n for n in names if n != "worlds" and n not in accepted]
        if extra and not var_kw:
            raise PluginError(f"{where}: config_table [{decl.name}] declares {extra[0]!r}, "
                              f"which the protocol does not take (its parameters: "
                              f"{', '.join(sorted(accepted)) or 'none'})")
    return decl


def _add(out: PluginTables, decl: ConfigTable, kind: str, name: str, plugin: str,
         registry: Any) -> None:
    have = out.tables.get(decl.name)
    if have is not None and have != decl:
        k, n, p = out.owners[decl.name][0]
        raise PluginError(f"config table [{decl.name}] is declared by two plugins: "
                          f"{registry.describe_plugin(p)} ({k} '{n}') and "
                          f"{registry.describe_plugin(plugin)} ({kind} '{name}'); expected "
                          "one declaration per table")
    out.tables[decl.name] = decl
    out.owners.setdefault(decl.name, []).append((kind, name, plugin))
    out.declared_by.setdefault((kind, name), []).append(decl.name)


def _default_text(value: Any) -> str:
    if value is REQUIRED:
        return "required"
    if value is ABSENT or value is None:
        return ""
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float) and math.isfinite(value):
        return f"{value:g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_default_text(v) for v in value) + "]"
    return str(value)


def tables_reference(index: PluginTables, registry: Any,
                     names: Iterable[str] | None = None) -> str:
    """Markdown: every declared table (or those in ``names``), who declares it, and a row
    per key (type, default, unit, range, meaning), for the reference docs."""
    out = []
    for t in sorted(index.tables) if names is None else names:
        decl = index.tables[t]
        who = "; ".join(f"{k} '{n}' of plugin {registry.describe_plugin(p)}"
                        for k, n, p in index.owners[t])
        out += [f"### `[{t}]`", "", (decl.doc + " " if decl.doc else "") + f"Declared by {who}."
                + (" In every config." if decl.always else ""), "",
                "| key | type | default | unit | range | meaning |",
                "|---|---|---|---|---|---|"]
        out += [f"| `{k.name}` | {k.type_text} | {_default_text(k.default)} | {k.unit} | "
                f"{k.range_text} | {k.doc} |" for k in decl.keys]
        out.append("")
    return "\n".join(out)


def protocol_key(proto: Any) -> str:
    """Where a protocol's parameters are in the config, for messages and
    :attr:`Resolved.origins`: its table (``table``, or its ``config_table``'s name), or
    ``"protocol NAME"`` for a protocol without one."""
    table = getattr(proto, "table", None)
    decl = getattr(proto, "config_table", None)
    return table if isinstance(table, str) and table else str(getattr(decl, "name", "")) or \
        f"protocol {getattr(proto, 'name', '?')}"


def unknown_table(name: str, index: PluginTables, *, file: str | None) -> InputError:
    """The error of a config table that is neither the core's nor declared by a plugin."""
    known = sorted({*CORE_TABLES, *index.tables})
    return InputError(f"unknown section{did_you_mean(name, known)}; expected one of "
                      f"{', '.join(known)} (the core's tables and those the loaded plugins "
                      "declare: a plugin's table needs its plugin)", file=file, key=name)
