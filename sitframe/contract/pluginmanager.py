"""Plugin discovery and component resolution.

:func:`get_plugin_manager` builds a fresh :class:`pluggy.PluginManager` per
run (never a module-level singleton), loads every setuptools entry point in
the group ``"sitframe"`` -- which is also how sitframe's own built-in plugins
are declared -- unless ``SITFRAME_DISABLE_PLUGIN_AUTOLOAD`` is set, and loads
loose ``.py`` files from plugin directories.

:class:`Registry` collects the component factories the registration hooks
return, keyed by kind and name, remembering which plugin registered each, so
that a duplicate name or a bad factory is reported with the plugin's name and
origin.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import inspect
import os
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import pluggy

from sitframe.contract import hookspecs
from sitframe.errors import PLUGIN_ERRORS, InputError, PluginError, did_you_mean
from sitframe.params import check_params

#: Entry-point group (and pluggy project name).
GROUP = "sitframe"
#: Set this environment variable to any non-empty value to skip entry points.
DISABLE_AUTOLOAD_ENV = "SITFRAME_DISABLE_PLUGIN_AUTOLOAD"

#: Component kinds, each with the registration hook that contributes it.
KINDS: dict[str, str] = {
    "sensor": "sitframe_sensors",
    "interpreter": "sitframe_interpreters",
    "reward": "sitframe_rewards",
    "behaviour": "sitframe_behaviours",
    "arbiter": "sitframe_arbiters",
    "protocol": "sitframe_protocols",
}


#: What to say of a registered instance (a hook returns factories: classes).
_INSTANCE = "; the hook must return the class, not an instance"

#: The names of sitframe's hooks (:mod:`sitframe.contract.hookspecs`).
HOOKS = tuple(n for n in vars(hookspecs) if n.startswith("sitframe_"))


@dataclass(frozen=True)
class PluginInfo:
    """Where a registered plugin came from."""

    name: str
    origin: str  # "entry point", "plugins-dir" or "registered"
    distribution: str | None = None
    version: str | None = None
    file: str | None = None

    def describe(self) -> str:
        if self.distribution:
            return f"{self.name} ({self.distribution} {self.version}, entry point)"
        if self.file:
            return f"{self.name} ({self.file})"
        return f"{self.name} ({self.origin})"


def get_plugin_manager(
    *,
    autoload: bool | None = None,
    plugins_dirs: Iterable[str | os.PathLike[str]] = (),
    plugins: Iterable[object] = (),
) -> pluggy.PluginManager:
    """Create a plugin manager with sitframe's hookspecs and the discovered plugins.

    Parameters
    ----------
    autoload
        Load setuptools entry points in group ``"sitframe"``. ``None`` (default)
        means yes unless the environment variable
        ``SITFRAME_DISABLE_PLUGIN_AUTOLOAD`` is set (tests use it to start from
        an empty manager).
    plugins_dirs
        Folders whose ``*.py`` files (not starting with ``_``) are imported and
        registered as plugins, in sorted order.
    plugins
        Extra plugin objects or modules to register (e.g. from a notebook).

    Returns
    -------
    pluggy.PluginManager
        With ``pm.sitframe_info: dict[str, PluginInfo]`` describing each plugin.

    Raises
    ------
    PluginError
        A plugin module failed to import (names the plugin and the file/line).
    """
    pm = pluggy.PluginManager(GROUP)
    pm.add_hookspecs(hookspecs)
    info: dict[str, PluginInfo] = {}
    pm.sitframe_info = info  # type: ignore[attr-defined]
    if autoload is None:
        autoload = not os.environ.get(DISABLE_AUTOLOAD_ENV)
    if autoload:
        _load_entry_points(pm, info)
    for folder in plugins_dirs:
        load_plugins_dir(pm, folder)
    for obj in plugins:
        register(pm, obj)
    try:  # a hook implementation whose name is no sitframe hook (a typo) is an error
        pm.check_pending()
    except pluggy.PluginValidationError as exc:
        name = pm.get_name(exc.plugin) or "?"
        who = info[name].describe() if name in info else name
        raise PluginError(f"plugin {who}: {' '.join(str(exc).split())}; the hooks are listed in "
                          "sitframe.contract.hookspecs") from None
    return pm


def register(pm: pluggy.PluginManager, plugin: object, name: str | None = None) -> str:
    """Register ``plugin`` on ``pm`` and record it as directly registered."""
    pname = name or getattr(plugin, "__name__", None) or type(plugin).__name__
    _register_checked(pm, plugin, pname, PluginInfo(pname, "registered"))
    return pname


def _register_checked(
    pm: pluggy.PluginManager, plugin: object, name: str, info: PluginInfo
) -> None:
    try:
        pm.register(plugin, name=name)
    except (pluggy.PluginValidationError, ValueError) as exc:
        raise PluginError(f"plugin {info.describe()} could not be registered: {exc}") from None
    for hook in HOOKS:  # a hook function without @sitframe.hookimpl would never be called
        if callable(getattr(plugin, hook, None)) and pm.parse_hookimpl_opts(plugin, hook) is None:
            raise PluginError(f"plugin {info.describe()}: {hook} is not decorated with "
                              "@sitframe.hookimpl, so it would never be called")
    # hooks on a class of the module: the module is registered, never the class
    classes = [c for c in vars(plugin).values() if isinstance(c, type)
               and c.__module__ == plugin.__name__] if isinstance(plugin, ModuleType) else []
    for cls in classes:
        hooks = [h for h in HOOKS if hasattr(getattr(cls, h, None), f"{GROUP}_impl")]
        if hooks:
            raise PluginError(f"plugin {info.describe()}: class {cls.__name__} implements "
                              f"{', '.join(hooks)}, but a plugin module's hooks are its "
                              "functions: sitframe never calls a class's (make them module "
                              "functions)")
    pm.sitframe_info[name] = info  # type: ignore[attr-defined]


def _load_entry_points(pm: pluggy.PluginManager, info: dict[str, PluginInfo]) -> None:
    """Register every entry point in group ``sitframe``.

    Two distributions declaring the same entry-point name are both loaded --
    the second as ``"<name>[<distribution>]"`` -- and the clash is recorded
    (:data:`ENTRY_POINT_CLASHES` on the manager, shown by ``sitframe plugins``
    and warned about once per run), instead of one silently winning by
    install order. The same distribution seen twice on ``sys.path`` (e.g. an
    editable install next to a built one) is loaded once.
    """
    seen: dict[str, tuple[str, str]] = {}  # entry-point name -> (distribution, module)
    clashes: list[str] = []
    pm.sitframe_clashes = clashes  # type: ignore[attr-defined]
    for dist in importlib.metadata.distributions():
        eps = [ep for ep in dist.entry_points if ep.group == GROUP and not pm.is_blocked(ep.name)]
        if not eps:
            continue
        # (each metadata access parses the METADATA file, README included: once per dist)
        dist_name, dist_version = dist.metadata["name"], dist.version
        for ep in eps:
            name = ep.name
            if name in seen:
                if seen[name] == (dist_name, ep.value):
                    continue
                clashes.append(f"entry point '{name}' is declared by {seen[name][0]} "
                               f"({seen[name][1]}) and by {dist_name} ({ep.value}); both are "
                               f"loaded, the second as '{name}[{dist_name}]'")
                name = f"{name}[{dist_name}]"
                if pm.get_plugin(name) is not None:
                    continue
            else:
                seen[name] = (dist_name, ep.value)
            pinfo = PluginInfo(name, "entry point", dist_name, dist_version)
            try:
                plugin = ep.load()
            except PLUGIN_ERRORS as exc:  # any import failure is the plugin's
                raise PluginError(
                    f"plugin {pinfo.describe()} failed to import ({ep.value}): "
                    f"{type(exc).__name__}: {exc}"
                ) from None
            _register_checked(pm, plugin, name, pinfo)


def load_plugins_dir(pm: pluggy.PluginManager, folder: str | os.PathLike[str]) -> list[str]:
    """Import every ``*.py`` file in ``folder`` and register it as a plugin.

    The plugin's name is ``"<stem>"`` (prefixed with ``dir:`` if it clashes
    with an entry-point plugin). A file already loaded is skipped (a folder
    named twice, by ``--plugins-dir`` and the config's ``[plugins] dirs``).
    Returns the registered names.
    """
    path = Path(folder)
    if not path.is_dir():
        raise InputError(f"plugins directory does not exist or is not a folder: {path}",
                         key="plugins_dir")
    names = []
    info: dict[str, PluginInfo] = pm.sitframe_info  # type: ignore[attr-defined]
    loaded = {Path(i.file).resolve() for i in info.values() if i.file}
    for file in sorted(path.glob("*.py")):
        if file.name.startswith("_") or file.resolve() in loaded:  # (a folder named twice)
            continue
        name = file.stem if pm.get_plugin(file.stem) is None else f"dir:{file.stem}"
        module = _import_file(file, name)
        _register_checked(pm, module, name, PluginInfo(name, "plugins-dir", file=str(file)))
        names.append(name)
    return names


def _import_file(file: Path, name: str) -> ModuleType:
    mod_name = f"sitframe_dirplugin_{name.replace(':', '_')}"
    spec = importlib.util.spec_from_file_location(mod_name, file)
    if spec is None or spec.loader is None:  # pragma: no cover - .py files always have one
        raise PluginError(f"plugin file {file}: cannot be imported")
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    try:
        spec.loader.exec_module(module)
    except SyntaxError as exc:
        sys.modules.pop(mod_name, None)
        raise PluginError(
            f"plugin file {file}:{exc.lineno}: syntax error: {exc.msg}"
        ) from None
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - even sys.exit() at import
        sys.modules.pop(mod_name, None)
        line = _traceback_line(exc, file)
        raise PluginError(
            f"plugin file {file}{line}: failed to import: {type(exc).__name__}: {exc}"
        ) from None
    return module


def _traceback_line(exc: BaseException, file: Path) -> str:
    tb = exc.__traceback__
    line = ""
    while tb is not None:
        if Path(tb.tb_frame.f_code.co_filename) == file:
            line = f":{tb.tb_lineno}"
        tb = tb.tb_next
    return line


@dataclass
class Entry:
    """One registered component factory and the plugin it came from."""

    kind: str
    name: str
    factory: Any
    plugin: str


@dataclass
class Registry:
    """Component factories by kind and name, with the plugin that gave each."""

    pm: pluggy.PluginManager
    entries: dict[str, dict[str, Entry]] = field(default_factory=dict)

    #: Component names registered by more than one plugin (``strict=False`` only):
    #: ``"<kind> '<name>': <plugin> and <plugin>"``.
    clashes: list[str] = field(default_factory=list)

    @classmethod
    def collect(cls, pm: pluggy.PluginManager, *, strict: bool = True) -> Registry:
        """Call every registration hook and index the factories.

        With ``strict=False`` (``sitframe plugins``) a component name that two
        plugins register is recorded in :attr:`clashes` (the first plugin
        keeps it) instead of raised, so everything can still be listed.

        Raises
        ------
        PluginError
            A plugin raised in a hook, returned something that is not a list
            of named factories, or registered a name another plugin already
            registered (both plugins are named).
        """
        reg = cls(pm)
        for kind, hook_name in KINDS.items():
            reg.entries[kind] = {}
            hook = getattr(pm.hook, hook_name)
            for impl in hook.get_hookimpls():  # registration order
                plugin_name = impl.plugin_name
                where = reg.describe_plugin(plugin_name)
                try:
                    result = impl.function()
                except PLUGIN_ERRORS as exc:  # report any plugin fault
                    raise PluginError(
                        f"plugin {where} raised in hook {hook_name}: "
                        f"{type(exc).__name__}: {exc}"
                    ) from None
                if result is None:
                    continue
                if not isinstance(result, list | tuple):
                    raise PluginError(
                        f"plugin {where}: hook {hook_name} must return a list of component "
                        f"factories, got {type(result).__name__}"
                    )
                for factory in result:
                    name = getattr(factory, "name", None)
                    if not isinstance(name, str) or not name or not callable(factory):
                        raise PluginError(
                            f"plugin {where}: hook {hook_name} returned {factory!r}, which is "
                            "not a callable with a non-empty string attribute 'name' (its name "
                            f"is {name!r}{'' if callable(factory) else _INSTANCE})"
                        )
                    if name in reg.entries[kind]:
                        other = reg.describe_plugin(reg.entries[kind][name].plugin)
                        msg = (f"{kind} name '{name}' is registered by two plugins: "
                               f"{other} and {where}")
                        if strict:
                            raise PluginError(msg)
                        reg.clashes.append(msg)
                        continue
                    reg.entries[kind][name] = Entry(kind, name, factory, plugin_name)
        return reg

    def describe_plugin(self, plugin_name: str) -> str:
        info = self.pm.sitframe_info.get(plugin_name)  # type: ignore[attr-defined]
        return info.describe() if info else plugin_name

    def names(self, kind: str) -> list[str]:
        return sorted(self.entries[kind])

    def get(
        self, kind: str, name: str, *, file: str | None = None, key: str | None = None
    ) -> Entry:
        """The factory registered as ``name`` for ``kind``, or an InputError listing the choices."""
        try:
            return self.entries[kind][name]
        except KeyError:
            choices = self.names(kind)
            raise InputError(
                f"unknown {kind} '{name}'{did_you_mean(str(name), choices)}; "
                f"available: {', '.join(choices) or '(none registered)'}",
                file=file,
                key=key,
            ) from None

    def create(
        self,
        kind: str,
        name: str,
        params: dict[str, Any],
        *,
        file: str | None = None,
        key: str | None = None,
        params_key: str | None = None,
    ) -> Any:
        """Create component ``name`` with keyword ``params``.

        Unknown parameter names, wrong values (``ValueError``/``TypeError``
        raised by the component) are reported as an :class:`InputError` located
        at ``file`` / ``key`` (a parameter at ``params_key``, default ``key``: a
        reward's parameters live in ``reward_params``, not under ``reward``); any
        other exception is a :class:`PluginError` naming the plugin.
        """
        entry = self.get(kind, name, file=file, key=key)
        params_key = key if params_key is None else params_key
        check_params(entry.factory, params, file=file, key=params_key)
        try:
            return entry.factory(**params)
        except InputError as exc:
            raise exc.at(file=file, key_prefix=params_key) from None
        except (ValueError, TypeError) as exc:
            f = entry.factory  # an instance where a class belongs: its __call__ was called
            hint = "" if isinstance(f, type) or inspect.isroutine(f) or hasattr(f, "func") \
                else f"{_INSTANCE} ({type(f).__name__}() was registered)"
            raise InputError(f"{exc} ({kind} '{name}' of plugin "
                             f"{self.describe_plugin(entry.plugin)}{hint})", file=file,
                             key=key) from None
        except PLUGIN_ERRORS as exc:
            raise PluginError(
                f"plugin {self.describe_plugin(entry.plugin)}: creating {kind} '{name}' "
                f"failed: {type(exc).__name__}: {exc}"
            ) from None

    def plugins_table(self) -> list[tuple[PluginInfo, dict[str, list[str]]]]:
        """Each plugin with the components it registers, per kind (for ``sitframe plugins``)."""
        out = []
        infos = self.pm.sitframe_info  # type: ignore[attr-defined]
        for pname, _plugin in sorted(self.pm.list_name_plugin()):
            comps: dict[str, list[str]] = {}
            for kind, by_name in self.entries.items():
                names = sorted(n for n, e in by_name.items() if e.plugin == pname)
                if names:
                    comps[kind] = names
            out.append((infos.get(pname, PluginInfo(pname, "registered")), comps))
        return out
