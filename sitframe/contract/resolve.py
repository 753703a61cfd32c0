"""Resolving a config against the plugin registry: fresh, checked, bound components.

:class:`Resolved` creates every component a run needs by the names the config
gives (the core knows no component by name), checks each against its protocol
(:mod:`sitframe.contract`), binds it to the run (:class:`sitframe.contract.records.RunContext`)
and loads the run's worlds. One is built per run (and per worker process).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.contract.checks import (
    BoundaryError,
    Origin,
    call,
    check_n_situations,
    check_protocol,
    fault,
    sensor_geometry,
    sensor_spec_mismatch,
)
from sitframe.contract.config import (
    DEFAULT_PROTOCOL,
    DEFAULT_SPACE,
    Component,
    Config,
    complete_tables,
)
from sitframe.contract.pluginmanager import Registry
from sitframe.contract.records import RunContext, SensorSpec, SpaceInfo
from sitframe.contract.tables import PluginTables, plugin_tables, protocol_key
from sitframe.errors import PLUGIN_ERRORS, InputError, PluginError, PluginFault
from sitframe.sim.robot import RobotParams
from sitframe.sim.world import World, load_world


@dataclass
class Resolved:
    """A config resolved against a registry: creates fresh, checked, bound components on demand.

    Every component is checked against its protocol when created and bound
    to the run (``bind(run)``, :class:`sitframe.contract.records.RunContext`) before it
    is used; :attr:`origins` names the plugin behind each config key for
    messages.
    """

    cfg: dict[str, Any]
    registry: Registry
    file: str | None = None
    robot: RobotParams = field(default_factory=RobotParams)
    _worlds: dict[str, World] = field(default_factory=dict)
    _fits: set[str] = field(default_factory=set)  # worlds whose start pose holds the robot
    origins: dict[str, Origin] = field(default_factory=dict)
    run: RunContext | None = None
    base_dir: str = "."
    tables: PluginTables = field(default_factory=PluginTables)

    @cached_property
    def config(self) -> Config:
        """The typed view of :attr:`cfg` (what the core reads)."""
        return Config.of(self.cfg)

    @classmethod
    def build(cls, cfg: dict[str, Any], registry: Registry, file: str | None = None,
              worlds: tuple[str, ...] = (), base_dir: str = ".") -> Resolved:
        """Resolve ``cfg``: create and bind each component once, so every mistake is found now.

        ``worlds`` names further worlds the caller will use (e.g. ``--world``);
        relative world paths resolve against ``base_dir`` (the config's folder).

        Plugin code that fails here (a property or ``bind`` that raises, a
        first reading that breaks the sensor's spec) fails before anything
        runs or is written: it is a :class:`PluginError` (CLI exit 2), not a
        :class:`PluginFault` of a run (exit 3, a log marked failed).

        ``cfg``'s plugin tables are checked against every declaration of the registry's
        plugins and completed in place (:func:`~sitframe.contract.config.complete_tables`):
        the config a run writes holds every table it uses.
        """
        try:
            return cls._build(cfg, registry, file, worlds, base_dir)
        except PluginFault as exc:
            raise PluginError(str(exc)) from exc

    @classmethod
    def _build(cls, cfg: dict[str, Any], registry: Registry, file: str | None,
               worlds: tuple[str, ...], base_dir: str) -> Resolved:
        tables = plugin_tables(registry)
        complete_tables(cfg, tables, file=file)
        try:
            robot = RobotParams(**cfg["robot"])
        except InputError as exc:
            raise exc.at(file=file, key_prefix="robot") from None
        except (ValueError, TypeError) as exc:
            raise InputError(str(exc), file=file, key="robot") from None
        res = cls(cfg, registry, file, robot, base_dir=base_dir, tables=tables)
        sensor = res._create("sensor", "sensor", res.config.sensor, bind=False)
        o = res.origins["sensor"]
        try:
            spec = SensorSpec(*sensor_geometry(sensor), str(getattr(sensor, "unit", "m")))
        except BoundaryError as exc:
            raise PluginFault(exc.args[1], where=str(o), method=exc.args[0]) from None
        except PLUGIN_ERRORS as exc:  # a property that raises is the plugin's
            raise fault(exc, o, "angles_deg") from exc
        interp = res._create("interpreter", "interpreter", res.config.interpreter, bind=False)
        c = call(res.origins["interpreter"], "n_situations", lambda: interp.n_situations)
        try:
            c = check_n_situations(c, unknown_ok=True)
        except BoundaryError as exc:
            raise PluginFault(str(exc), where=str(res.origins["interpreter"]),
                              method="n_situations") from None
        e = res.config.experiment
        loaded = {n: res.world(n, res.config.world_key(n))
                  for n in dict.fromkeys([*res.stage_worlds(), *worlds])}
        spaces = {DEFAULT_SPACE: SpaceInfo(DEFAULT_SPACE, None if c is None else int(c),
                                           tuple(range(spec.dim)),
                                           tuple(res.config.readers(DEFAULT_SPACE)))}
        space_interps = {name: res._space(name, spec) for name in res.config.spaces}
        spaces |= {name: info for name, (_i, info) in space_interps.items()}
        res.run = RunContext(robot, spec, tuple(res.config.behaviours),
                             None if c is None else int(c), loaded, e.seed, e.iterations,
                             e.default_speed, spaces=spaces,
                             tables={t: dict(res.cfg[t]) for t in tables.tables if t in res.cfg})
        res._bind(sensor, "sensor")
        res._check_sensor(sensor, spec, loaded[e.world])
        res._bind(interp, "interpreter")
        for name, (sp_interp, _info) in space_interps.items():
            res._bind(sp_interp, f"spaces.{name}")
        res.behaviours()
        res.arbiter()
        for name in registry.names("protocol"):  # a protocol's own table is checked now
            if res.protocol_table(name) in res.config.tables:
                res.protocol(name)
        return res

    def stage_worlds(self) -> list[str]:
        """The worlds of the run's stages, once each: the learning world, the collection
        rooms (if it collects) and, if it evaluates, the worlds of the default protocol's
        table (``[evaluate] worlds``, loaded for every run that evaluates, whichever protocol
        it uses, as before protocols declared their tables)."""
        names = self.config.worlds()
        if "evaluate" in self.config.experiment.stages and \
                DEFAULT_PROTOCOL in self.registry.entries.get("protocol", {}):
            table = self.protocol_table(DEFAULT_PROTOCOL)
            worlds = self.config.tables.get(table or "", {}).get("worlds")
            if isinstance(worlds, list):
                names += [w for w in worlds if isinstance(w, str)]
        return list(dict.fromkeys(names))

    def _space(self, name: str, spec: SensorSpec) -> tuple[Any, SpaceInfo]:
        """Create space ``name``'s interpreter (unbound) and describe the space; its ``view``
        must name readings the sensor has, and its interpreter must not evolve."""
        section = self.config.spaces[name]
        key = f"spaces.{name}"
        view = tuple(range(spec.dim)) if section.view is None else section.view
        for i, v in enumerate(view):
            if v >= spec.dim:
                raise InputError(f"reading {v} is outside the sensor's {spec.dim} readings "
                                 f"(indices 0-{spec.dim - 1}, at "
                                 f"{', '.join(f'{a:+g}' for a in spec.angles_deg)} deg)",
                                 file=self.file, key=f"{key}.view[{i}]")
        interp = self._create("interpreter", key, section.interpreter, bind=False)
        if getattr(interp, "evolving", False):
            raise InputError(f"interpreter '{section.interpreter.name}' evolves its situations, "
                             "which only the [interpreter] (the default space) may; expected "
                             "a fixed interpreter (e.g. fcm) for a space of its own",
                             file=self.file, key=f"{key}.component")
        c = call(self.origins[key], "n_situations", lambda: interp.n_situations)
        try:
            c = check_n_situations(c, unknown_ok=True)
        except BoundaryError as exc:
            raise PluginFault(str(exc), where=str(self.origins[key]),
                              method="n_situations") from None
        return interp, SpaceInfo(name, None if c is None else int(c), view,
                                 tuple(self.config.readers(name)))

    def space_view(self, name: str) -> np.ndarray | None:
        """The reading indices space ``name`` sees (``None``: all, in order)."""
        view = self.run.spaces[name].view
        return None if view == tuple(range(self.run.sensor.dim)) else np.asarray(view, np.intp)

    def space_interpreter(self, name: str) -> Any:
        """A fresh, bound interpreter of space ``name`` (``"default"``: :meth:`interpreter`)."""
        if name == DEFAULT_SPACE:
            return self.interpreter()
        return self._create("interpreter", f"spaces.{name}",
                            self.config.spaces[name].interpreter)

    def space_key(self, name: str) -> str:
        """The config key of space ``name``'s interpreter (for :attr:`origins`)."""
        return "interpreter" if name == DEFAULT_SPACE else f"spaces.{name}"

    def _check_sensor(self, sensor: Any, spec: SensorSpec, world: World) -> None:
        """Read once at the learning world's start: the reading must match the declared spec."""
        o = self.origins["sensor"]
        reading = call(o, "read", sensor.read, world, world.start.copy(),
                       np.random.default_rng(0))
        why = sensor_spec_mismatch(reading, spec.dim, spec.max_range)
        if why is not None:
            raise PluginFault(why, where=str(o), method="read")

    def _create(self, kind: str, key: str, table: Component, *, bind: bool = True,
                needs: tuple[str, ...] = ()) -> Any:
        comp = self.registry.create(kind, table.name, table.params, file=self.file, key=key,
                                    params_key=f"{key}_params" if kind == "reward" else None)
        entry = self.registry.get(kind, table.name)
        origin = Origin(self.registry.describe_plugin(entry.plugin), kind, entry.name, key,
                        entry.plugin)
        self.origins[key] = origin
        check_protocol(comp, origin, needs=needs)
        if bind:
            self._bind(comp, key)
        return comp

    def _bind(self, comp: Any, key: str) -> None:
        fn = getattr(comp, "bind", None)
        if fn is None:
            return
        o = self.origins[key]
        run = dataclasses.replace(self.run, component=key)
        space = key.split(".", 1)[1] if key.startswith("spaces.") else \
            self.config.space_of(key.removesuffix(".reward"))
        if space != DEFAULT_SPACE and space in run.spaces:  # (the component's own space)
            info = run.spaces[space]
            run = dataclasses.replace(run, space=space, n_situations=info.n_situations,
                                      sensor=dataclasses.replace(
                                          run.sensor, angles_deg=run.sensor.angles_deg[
                                              list(info.view)]) if key.startswith("spaces.")
                                      else run.sensor)
        try:
            fn(run)
        except InputError as exc:
            raise exc.at(file=self.file, key_prefix=key) from None
        except (ValueError, TypeError) as exc:  # the component's parameters do not fit the run
            raise InputError(f"{exc} ({o.kind} '{o.name}' of plugin {o.plugin}, at bind)",
                             file=self.file, key=key) from None
        except (KeyboardInterrupt, PluginFault):
            raise
        except PLUGIN_ERRORS as exc:  # any other fault in plugin code
            raise fault(exc, o, "bind") from exc

    def sensor(self) -> Any:
        return self._create("sensor", "sensor", self.config.sensor)

    def interpreter(self) -> Any:
        return self._create("interpreter", "interpreter", self.config.interpreter)

    def arbiter(self) -> Any:
        table = self.config.arbiter
        return self._create("arbiter", "arbiter", table, needs=self._learner_needs(table))

    def _learner_needs(self, table: Component) -> tuple[str, ...]:
        """What a behaviour's or the arbiter's table makes it need (``learn``, ``policy``)."""
        if table.reward is None:
            return ()
        return ("learn", "policy") if "evaluate" in self.config.experiment.stages else ("learn",)

    def arbiter_reward(self) -> Any | None:
        """The reward the arbiter learns from (``[arbiter] reward = ...``), or ``None``."""
        return self._reward("arbiter", self.config.arbiter)

    def _reward(self, key: str, table: Component) -> Any | None:
        """The reward a behaviour's or the arbiter's table names (``reward``, ``reward_params``)."""
        if table.reward is None:
            return None
        return self._create("reward", f"{key}.reward", Component(table.reward,
                                                                 table.reward_params))

    def behaviours(self) -> dict[str, tuple[Any, Any | None]]:
        """Label -> (behaviour, reward or None), in config order."""
        out = {}
        for label, table in self.config.behaviours.items():
            key = f"behaviours.{label}"
            needs = self._learner_needs(table) + \
                (("load_policy",) if table.policy_from is not None else ())
            out[label] = (self._create("behaviour", key, table, needs=needs),
                          self._reward(key, table))
        return out

    def protocol_name(self, default: str | None = DEFAULT_PROTOCOL) -> str | None:
        """The evaluation protocol the run's components name (``evaluation_protocol``).

        A component asks for the protocol its behaviour is judged by with a
        class attribute, e.g. ``evaluation_protocol = "goal-episodes"``; two
        components naming different protocols are an input error; none: ``default``.
        """
        comps = [b for b, _r in self.behaviours().values()] + [self.arbiter()]
        names = sorted({n for c in comps if (n := getattr(c, "evaluation_protocol", None))})
        if len(names) > 1:
            raise InputError(f"the components ask for different evaluation protocols "
                             f"({', '.join(names)}); expected one", file=self.file,
                             key="behaviours")
        return names[0] if names else default

    def protocol(self, name: str) -> Any:
        """A fresh evaluation protocol ``name``, created from its config table (but
        ``worlds``); a protocol that declares no table gets its defaults."""
        table = self.protocol_table(name)
        params = {k: v for k, v in self.config.tables.get(table or "", {}).items()
                  if k != "worlds"}
        key = table or protocol_key(self.registry.get("protocol", name).factory)
        return self._create("protocol", key, Component(name, params))

    def protocol_table(self, name: str) -> str | None:
        """The config table holding protocol ``name``'s parameters (``None``: it has none)."""
        self.registry.get("protocol", name, file=self.file, key="behaviours")
        for table, owners in self.tables.owners.items():
            if ("protocol", name) in ((k, n) for k, n, _p in owners):
                return table
        return None

    def protocol_worlds(self, name: str) -> list[str]:
        """The worlds of protocol ``name``'s table, loaded and checked (``check_world``); a
        protocol that declares no table runs in the default protocol's (``[evaluate]``)."""
        proto = self.protocol(name)
        table = self.protocol_table(name)
        if table is None and name != DEFAULT_PROTOCOL and \
                DEFAULT_PROTOCOL in self.registry.entries.get("protocol", {}):
            table = self.protocol_table(DEFAULT_PROTOCOL)  # no table: the default's worlds
        names = self.config.tables.get(table or "", {}).get("worlds")
        if table is None:
            raise InputError(f"the evaluation protocol '{name}' declares no config table, so "
                             "it names no worlds to run its episodes in; expected a protocol "
                             "whose table has 'worlds' (or no evaluate stage)", file=self.file,
                             key="experiment.stages")
        if names is None:
            raise InputError(f"missing: the worlds the evaluation protocol '{name}' runs its "
                             f"episodes in (expected worlds = [\"...\"] in [{table}])",
                             file=self.file, key=f"{table}.worlds")
        if not isinstance(names, list) or not names or \
                not all(isinstance(n, str) and n for n in names):
            raise InputError(f"expected a non-empty list of world names, got {names!r}",
                             file=self.file, key=f"{table}.worlds")
        for j, wname in enumerate(names):
            key = f"{table}.worlds[{j}]"
            world = self.world(wname, key=key)
            if hasattr(proto, "check_world"):
                try:
                    call(self.origins[table], "check_world", proto.check_world, world)
                except InputError as exc:
                    raise InputError(exc.message, file=self.file, key=key) from None
        return names

    def world(self, name: str, key: str = "experiment.world") -> World:
        """The world ``name``: a shipped name, or a .toml path relative to :attr:`base_dir`
        (the config file's folder)."""
        if name not in self._worlds:
            path: str | Path = name  # a shipped name
            if name.endswith(".toml") or "/" in name:
                path = Path(name)
                if not path.is_absolute() and self.base_dir not in ("", "."):
                    path = Path(self.base_dir) / path
            try:
                self._worlds[name] = load_world(path)
            except InputError as exc:
                if exc.file is None or (isinstance(path, Path) and not path.is_file()):
                    # the path itself is wrong: the config's key is where to fix it
                    where = f" ({exc.file})" if exc.file else ""
                    raise InputError(f"{exc.message}{where}", file=self.file, key=key) from None
                raise
        w = self._worlds[name]
        # (collection rooms followed along their trajectories are not driven from the start
        # pose; a room is checked where it is first used from its start, whatever loaded it)
        along = key.startswith("collect") and self.config.collect.mode == "trajectory"
        if not along and name not in self._fits:
            clear = float(w.clearance(w.start[None, :2])[0])
            if clear < self.robot.radius:
                raise InputError(f"the robot disc (radius {self.robot.radius:g} m) does not fit at "
                                 f"the start pose of world '{name}' (clearance {clear:.3g} m); "
                                 f"expected robot.radius <= {clear:.3g} or another world",
                                 file=self.file, key="robot.radius")
            self._fits.add(name)
        return w
