"""Run configs: TOML files (or shipped presets) validated into a plain dict.

A config has these tables (every key optional unless noted; defaults are the
thesis's Table A.1):

``[experiment]``
    ``name``, ``description``, ``seed`` (int), ``trials`` (learning trials),
    ``iterations`` (l, per trial), ``stages`` (subset of
    ``["collect", "cluster", "learn", "evaluate"]``), ``world`` (the learning
    world: a shipped name or a .toml path), ``default_speed`` (m/s, when no
    behaviour proposes a speed),
    ``clusters_from`` (path of a log whose fitted situations are reused;
    collect and cluster are then skipped).
``[robot]``
    Fields of :class:`sitframe.sim.robot.RobotParams` (radius, turn-rate limit,
    substep, speed limits, collision recovery).
``[sensor]``
    ``component`` (required; e.g. ``"pioneer-sonar"``) and its parameters.
``[collect]``
    ``mode`` (``"trajectory"``, ``"wander"`` or ``"both"``), ``worlds``, ``speed`` (m/s),
    ``rate_hz`` (samples per second), ``wander_samples`` (per world).
``[interpreter]``
    ``component`` (e.g. ``"fcm"``) and its parameters (c, m, trials ...).
``[behaviours.LABEL]``
    One table per behaviour: ``component`` (required), optional ``reward``
    (a reward component name: the behaviour learns from it), optional
    ``reward_params`` table, optional ``policy_from = {log = "...", trial = 0,
    behaviour = "LABEL"}`` to start from a learned policy (``trial = "best"``
    picks the trial whose frozen rule base ranked best on collisions and
    coverage when evaluated in the log's own learning world; see
    :func:`sitframe.logs.policies.best_trial`; a table ``trial = {world = "W",
    episodes = 100, score = "collision_free_rate", seed = 0}`` picks the
    trial that scores highest in that many episodes of the evaluation
    protocol in world W, see :func:`sitframe.runs.evaluation.select_trial`), then the
    behaviour's own parameters.
``[arbiter]``
    ``component`` (default ``"single"``) and its parameters.
Plugins' tables
    Any other table is a plugin's: a component declares it (:mod:`sitframe.contract.tables`),
    and it is checked, filled in and logged like the core's. The built-in evaluation
    protocols declare theirs so: ``[evaluate]`` (``worlds``, ``iterations``) is the
    ``frozen`` protocol's (``plugins/frozen_evaluation.py``), ``[goal]`` (``episodes``,
    ``timeout``, ``min_distance``, ``worlds``, ``pairs``, ``radius``, ``margin``, optionally
    ``train``, ``train_detour``, ``detour_ratio``) the ``goal-episodes`` protocol's
    (``plugins/goal_episodes.py``).
``[spaces.NAME]``
    A *situation space* of its own (optional; :class:`SpaceSection`): an
    interpreter table like ``[interpreter]`` (``component`` and its
    parameters) plus the reserved keys ``view`` (which readings it sees:
    indices into the sensor's reading, default all), ``clusters_from`` (a
    log whose fitted ``[interpreter]`` situations it reuses) and ``collect``
    (overrides of ``[collect]`` for data of its own). A behaviour (or the
    arbiter) reads it with ``space = "NAME"`` in its table; the
    ``[interpreter]`` is the space named ``"default"``, which every
    component without ``space`` reads. Spaces are absent from a config that
    does not use them, so a run with one space is what it always was.
``[prerequisites]``
    ``"LOG PATH" = "EXPERIMENT"``: a log this config reads (``clusters_from``,
    ``policy_from.log``) and the experiment (preset name or .toml path) that
    makes it; ``sitframe run`` makes a missing one first, or reuses a complete
    one of the same config (:func:`sitframe.runs.prepare.make_prerequisites`).
``[plugins]``
    ``dirs``: folders of loose plugin modules, relative to the config file.
    Every ``*.py`` file in them is imported, i.e. **runs**, when the config
    is loaded (as pytest imports ``conftest.py``): use only configs you
    trust. ``run --resume`` does not import folders named only by a log.

Paths in a config (world files, ``clusters_from``, ``policy_from.log``,
``plugins.dirs``) resolve against the config file's folder; a world given
as a bare name (no ``/``, no ``.toml``) is a shipped world. Text is stored
in the log as TOML, so any string round-trips; behaviour labels name HDF5
groups and may not be empty, ``.`` or contain ``/``.

Component parameters are checked against the component's signature when the
run resolves its components (unknown names get a did-you-mean); everything
else is checked here: the core tables, and the plugins' tables that the installed
(entry-point) plugins declare. A table only a plugin folder (``--plugins-dir``,
``[plugins] dirs``) declares is checked when the run resolves its components
(:func:`complete_tables`), as its plugins are loaded only then. Every error is an
:class:`~sitframe.errors.InputError` naming the file and the key path.

Why one module of this size: every core table is declared, checked and typed here, so
that the config reference, the validation and the typed view read one declaration.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import importlib.resources
import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sitframe import params as P
from sitframe.contract.pluginmanager import DISABLE_AUTOLOAD_ENV, Registry, get_plugin_manager
from sitframe.contract.tables import PluginTables, plugin_tables, unknown_table
from sitframe.errors import InputError, did_you_mean
from sitframe.params import ABSENT, REQUIRED, Key, Table
from sitframe.sim.robot import RobotParams

STAGES = ("collect", "cluster", "learn", "evaluate")

#: Upper bounds of the counts (beyond them arrays do not fit in memory or the
#: log's 64-bit integer attributes cannot hold the value).
MAX_SEED = 2**63 - 1
MAX_TRIALS = 100_000
MAX_ITERATIONS = 10_000_000
MAX_RATE_HZ = 1000.0
MIN_RATE_HZ = 0.01
COLLECTION_ROOMS = ["collect-1", "collect-2", "collect-3", "collect-4", "collect-5"]


def _run_name(value: str, key: str) -> str:
    """A run name: no control characters, and a relative path inside logs/ (the default log
    is logs/<name>.h5; a name may nest, as sweeps' "sweep/point" do)."""
    if any(ord(ch) < 32 for ch in value):
        raise InputError(f"expected a name without control characters, got {value!r}", key=key)
    parts = value.replace("\\", "/").split("/")
    if value.startswith(("/", "\\")) or any(p in ("", ".", "..") for p in parts) \
            or ":" in value:
        raise InputError(f"expected a name that is a relative path inside logs/ (no leading "
                         f"'/', no empty, '.' or '..' part, no ':'), got {value!r}", key=key)
    return value


def _component(default: str | P._Marker, what: str) -> Key:
    return Key("component", "string", default, f"the registered name of the {what}")


_REWARD = Key("reward", "string", ABSENT, "a reward component: the behaviour (or arbiter) "
              "learns from it")
_REWARD_PARAMS = Key("reward_params", "table", ABSENT, "the reward's parameters (needs "
                     "reward)")
_SPACE = Key("space", "string", ABSENT, "the situation space it reads: a [spaces.NAME] "
             "table's NAME (default: the [interpreter]'s space, \"default\")")

#: The tables of a run config, declared once: :func:`validate_config` checks a config with
#: them, :data:`DEFAULTS` comes from them, and the documentation's config reference is made
#: from them. A component table (``free``) takes the component's own parameters besides its
#: declared keys; those are checked by the component, and listed with it
#: (:func:`sitframe.params.declared_params`). ``[robot]`` is the fields of
#: :class:`~sitframe.sim.robot.RobotParams`, which checks them.
EXPERIMENT = Table("experiment", doc="What runs, how long and where.", keys=(
    Key("name", "string", "experiment", "the run's name; its log is logs/<name>.h5",
        check=_run_name),
    Key("description", "text", "", "one line on what the run is for"),
    Key("seed", "integer", 0, "the run seed: every random choice of the run derives from it",
        lo=0, hi=MAX_SEED),
    Key("trials", "integer", 11, "independent learning trials", lo=1, hi=MAX_TRIALS),
    Key("iterations", "integer", 5000, "iterations per learning trial (the thesis's l); one "
        "iteration is one control period of the robot", lo=1, hi=MAX_ITERATIONS),
    Key("stages", "choices", list(STAGES), "the stages to run, in this order",
        choices=STAGES),
    Key("world", "string", "training", "the learning world: a shipped world's name or a "
        ".toml path"),
    Key("default_speed", "number", 0.15, "the speed when no behaviour proposes one",
        unit="m/s", lo=0.0, lo_open=True),
    Key("clusters_from", "path", "", "a log whose fitted situations are reused (the collect "
        "and cluster stages are skipped); empty: none"),
    Key("rooms", "names", ABSENT, "learn over a family of rooms: each learning trial is a "
        "chain of episodes, each in a room and from a free start pose drawn by the trial's "
        "Generator (the rooms in shuffled rounds); absent: the trial runs in world only"),
    Key("episode_iterations", "integer", ABSENT, "iterations of one episode of a learning "
        "trial over rooms (needs rooms; default 250)", lo=1, hi=MAX_ITERATIONS),
    Key("tight_starts", "number", ABSENT, "the share of a learning trial's episodes over "
        "rooms that start in a tight place (the least clearance of 20 free poses drawn) "
        "instead of a uniform free pose: a curriculum for rarely met situations (needs "
        "rooms; default 0)", lo=0.0, hi=1.0),
    Key("candidates", "integer", ABSENT, "rule bases a learning trial learns one after "
        "another (iterations / candidates each, the learners reset in between), keeping the "
        "one that scores best in validation_rooms (needs them; default 1)", lo=1, hi=1000),
    Key("validation_rooms", "names", ABSENT, "the rooms the candidates are judged in, each "
        "from its start pose, frozen (needs candidates)"),
    Key("validation_iterations", "integer", ABSENT, "iterations of a candidate's run in each "
        "validation room (needs candidates; default 500)", lo=1, hi=MAX_ITERATIONS),
))
#: Iterations of one episode of a learning trial over ``rooms`` when the config does not say.
ROOM_EPISODE_ITERATIONS = 250
#: Iterations of a candidate's run in a validation room when the config does not say.
VALIDATION_ITERATIONS = 500
ROBOT = Table("robot", doc="The simulated robot: the fields of RobotParams, which checks them.",
              keys=(), free=True)
SENSOR = Table("sensor", doc="The sensor: a component and its parameters.",
               keys=(_component("pioneer-sonar", "sensor"),), free=True)
COLLECT = Table("collect", doc="How the sensor data for the cluster stage is recorded.", keys=(
    Key("mode", "choice", "trajectory", "follow each room's forced trajectories, wander with "
        "a reflex, or both", choices=("trajectory", "wander", "both")),
    Key("worlds", "names", COLLECTION_ROOMS, "the rooms data is collected in"),
    Key("speed", "number", 0.15, "the speed while collecting", unit="m/s", lo=0.0,
        lo_open=True),
    Key("rate_hz", "number", 2.0, "readings recorded per second", unit="Hz", lo=MIN_RATE_HZ,
        hi=MAX_RATE_HZ),
    Key("wander_samples", "integer", 300, "readings recorded per room when wandering", lo=1,
        hi=MAX_ITERATIONS),
))
INTERPRETER = Table("interpreter", doc="The situation interpreter: a component and its "
                    "parameters.", keys=(_component("fcm", "situation interpreter"),), free=True)
BEHAVIOUR = Table("behaviours.LABEL", doc="One table per behaviour, LABEL naming it in the log "
                  "and the arbiter (not empty, not '.', no '/'): a component, what it learns "
                  "from, where it starts from, and its parameters.", keys=(
    _component(REQUIRED, "behaviour"),
    _REWARD,
    _REWARD_PARAMS,
    Key("policy_from", "table", ABSENT, "start from a learned policy: {log = \"path.h5\", "
        "trial = K, behaviour = \"LABEL\"} (the table below)"),
    _SPACE,
), free=True)
POLICY_FROM = Table("behaviours.LABEL.policy_from", doc="A learned policy to start from (or be "
                    "frozen at).", keys=(
    Key("log", "string", REQUIRED, "the log that learned it (a path)"),
    Key("trial", "trial", 0, "which trial's policy: an index; \"best\" (the smallest rank sum of "
        "fewest collisions and most coverage, evaluated in the log's learning world); or a "
        "selection table (below)"),
    Key("behaviour", "string", ABSENT, "the behaviour's label in that log (default: this "
        "table's LABEL)"),
))
SELECTION = Table("behaviours.LABEL.policy_from.trial", doc="The trial whose policy scores "
                  "highest in a batch of evaluation-protocol episodes "
                  "(sitframe.runs.evaluation.select_trial).", keys=(
    Key("world", "string", REQUIRED, "the world the trials are compared in (a learning room, "
        "never a test room)"),
    Key("episodes", "integer", 100, "episodes per trial", lo=1),
    Key("score", "string", "collision_free_rate", "the figure to maximise (a key of "
        "evaluate --goal-episodes --json)"),
    Key("seed", "integer", 0, "seed of the episodes", lo=0),
))
ARBITER = Table("arbiter", doc="The arbiter that fuses the behaviours' proposals: a component, "
                "what it learns from, and its parameters.",
                keys=(_component("single", "arbiter"), _REWARD, _REWARD_PARAMS, _SPACE),
                free=True)
SPACE = Table("spaces.NAME", doc="A situation space of its own (optional, absent unless "
              "given): an interpreter like [interpreter] (a component and its parameters) "
              "over a view of the readings; a behaviour or the arbiter reads it with "
              "space = \"NAME\". NAME is not \"default\" (the [interpreter]'s space).", keys=(
    _component(REQUIRED, "space's situation interpreter"),
    Key("view", "numbers", ABSENT, "the readings it sees: indices into the sensor's reading "
        "(0 = the first beam); default all, in order", lo=0),
    Key("clusters_from", "path", ABSENT, "a log whose fitted [interpreter] situations it "
        "reuses (no collect or cluster of its own)"),
    Key("collect", "table", ABSENT, "[collect] keys overridden for the data it clusters"),
), free=True)
PREREQUISITES = Table("prerequisites", doc="Logs this config reads and the experiments that "
                      "make them: \"LOG PATH\" = \"EXPERIMENT\" (a preset name or a .toml "
                      "path); sitframe run makes a missing one first, or reuses a complete "
                      "one of the same config. Optional; absent unless given.", keys=(), free=True)
PLUGINS = Table("plugins", doc="Loose plugin modules. Every *.py file in these folders is "
                "imported, that is run, when the config is loaded: use only configs you "
                "trust.", keys=(
    Key("dirs", "names", [], "folders of loose plugin modules, relative to the config file",
        lo=0),
))

#: Every table of a run config, in the order of a config's text.
TABLES: tuple[Table, ...] = (EXPERIMENT, ROBOT, SENSOR, COLLECT, INTERPRETER, BEHAVIOUR,
                             ARBITER, PLUGINS)
#: Defaults of the core sections (from :data:`TABLES`); component tables are free-form.
DEFAULTS: dict[str, dict[str, Any]] = {
    ("behaviours" if t is BEHAVIOUR else t.name): ({} if t is BEHAVIOUR else t.defaults())
    for t in TABLES}
DEFAULT_PROTOCOL = "frozen"  # the evaluation protocol of a run whose components name none
#: Optional sections without defaults (absent from a config that does not use them, so the
#: config's text, and so its hash, stays what it was before they existed).
OPTIONAL_SECTIONS = ("prerequisites", "spaces")
#: The core's tables, in the order a config lists them; plugins' tables go between
#: ``arbiter`` and ``plugins``, by name.
_BEFORE_PLUGIN_TABLES = ("experiment", "robot", "sensor", "collect", "interpreter",
                         "behaviours", "arbiter")
_CORE_TABLES = {t.name: t for t in (EXPERIMENT, COLLECT, PLUGINS)}
_CORE_KEYS = {s: set(v) | {k.name for k in _CORE_TABLES[s].keys} if s in _CORE_TABLES
              else set(v) for s, v in DEFAULTS.items() if s not in ("behaviours",)}
_COMPONENT_SECTIONS = ("sensor", "interpreter", "arbiter")
#: Keys of a ``[behaviours.LABEL]`` (or ``[arbiter]``) table that the core reads and that
#: are not the component's parameters (the one definition; resolve and sweep use it).
META_KEYS = tuple(k.name for k in BEHAVIOUR.keys)
#: The name of the situation space of ``[interpreter]`` (every component's unless its table
#: names another ``space``).
DEFAULT_SPACE = "default"
#: Keys of a ``[spaces.NAME]`` table that are not the interpreter's parameters.
SPACE_KEYS = tuple(k.name for k in SPACE.keys)


@dataclass(frozen=True)
class Component:
    """A component table: the registered ``name`` and the component's own ``params``.

    ``reward``, ``reward_params``, ``policy_from`` and ``space`` are the reserved keys
    (:data:`META_KEYS`) the core reads from behaviour and arbiter tables.
    """

    name: str
    params: dict[str, Any]
    reward: str | None = None
    reward_params: dict[str, Any] = dataclasses.field(default_factory=dict)
    policy_from: dict[str, Any] | None = None
    space: str = DEFAULT_SPACE

    @classmethod
    def of(cls, table: dict[str, Any]) -> Component:
        return cls(table["component"], {k: v for k, v in table.items() if k not in META_KEYS},
                   table.get("reward"), dict(table.get("reward_params", {})),
                   table.get("policy_from"), str(table.get("space", DEFAULT_SPACE)))


@dataclass(frozen=True)
class SpaceSection:
    """``[spaces.NAME]``: a situation space of its own (module docstring).

    Attributes
    ----------
    interpreter
        The interpreter (component and parameters), as ``[interpreter]``.
    view
        Indices of the readings it sees (into the sensor's reading), or ``None``: all.
    clusters_from
        A log whose fitted ``[interpreter]`` situations it reuses (``""``: fitted here).
    collect
        Overrides of the ``[collect]`` table for the data it is fitted on.
    """

    interpreter: Component
    view: tuple[int, ...] | None
    clusters_from: str
    collect: dict[str, Any]

    @classmethod
    def of(cls, table: dict[str, Any]) -> SpaceSection:
        view = table.get("view")
        return cls(Component(table["component"],
                             {k: v for k, v in table.items() if k not in SPACE_KEYS}),
                   None if view is None else tuple(int(i) for i in view),
                   str(table.get("clusters_from", "")), dict(table.get("collect", {})))


@dataclass(frozen=True)
class ExperimentSection:
    """``[experiment]``: what runs, how long, where (see the module docstring)."""

    name: str
    description: str
    seed: int
    trials: int
    iterations: int
    stages: tuple[str, ...]
    world: str
    default_speed: float
    clusters_from: str
    rooms: tuple[str, ...] = ()
    episode_iterations: int = ROOM_EPISODE_ITERATIONS
    candidates: int = 1
    validation_rooms: tuple[str, ...] = ()
    validation_iterations: int = VALIDATION_ITERATIONS
    tight_starts: float = 0.0


@dataclass(frozen=True)
class CollectSection:
    """``[collect]``: how sensor data for the cluster stage is recorded."""

    mode: str
    worlds: tuple[str, ...]
    speed: float
    rate_hz: float
    wander_samples: int


@dataclass(frozen=True)
class Config:
    """A validated config, typed: what the core reads (built by :meth:`of`).

    The plain dict it is built from stays the config's serial form (the
    log's TOML, sweep keys); ``tables`` holds every table as validated, for
    plugins that read a table by name (an evaluation protocol's, e.g. ``[goal]``,
    and any table a plugin declares).
    """

    experiment: ExperimentSection
    robot: dict[str, Any]
    sensor: Component
    collect: CollectSection
    interpreter: Component
    behaviours: dict[str, Component]
    arbiter: Component
    plugin_dirs: tuple[str, ...]
    prerequisites: dict[str, str]
    tables: dict[str, dict[str, Any]]
    spaces: dict[str, SpaceSection] = dataclasses.field(default_factory=dict)

    @classmethod
    def of(cls, cfg: dict[str, Any]) -> Config:
        """The typed view of a config validated by :func:`validate_config`."""
        e, c = cfg["experiment"], cfg["collect"]
        return cls(
            ExperimentSection(e["name"], e["description"], int(e["seed"]), int(e["trials"]),
                              int(e["iterations"]), tuple(e["stages"]), e["world"],
                              float(e["default_speed"]), e["clusters_from"],
                              tuple(e.get("rooms", ())),
                              int(e.get("episode_iterations", ROOM_EPISODE_ITERATIONS)),
                              int(e.get("candidates", 1)), tuple(e.get("validation_rooms", ())),
                              int(e.get("validation_iterations", VALIDATION_ITERATIONS)),
                              float(e.get("tight_starts", 0.0))),
            dict(cfg["robot"]), Component.of(cfg["sensor"]),
            CollectSection(c["mode"], tuple(c["worlds"]), float(c["speed"]),
                           float(c["rate_hz"]), int(c["wander_samples"])),
            Component.of(cfg["interpreter"]),
            {label: Component.of(t) for label, t in cfg["behaviours"].items()},
            Component.of(cfg["arbiter"]),
            tuple(cfg["plugins"]["dirs"]), dict(cfg.get("prerequisites", {})),
            {k: t for k, t in cfg.items() if isinstance(t, dict)},
            {n: SpaceSection.of(t) for n, t in cfg.get("spaces", {}).items()})

    def space_of(self, key: str) -> str:
        """The situation space a component reads: ``key`` is ``"behaviours.LABEL"`` or
        ``"arbiter"`` (anything else: the default space)."""
        if key == "arbiter":
            return self.arbiter.space
        if key.startswith("behaviours.") and key.count(".") == 1:
            return self.behaviours[key.split(".", 1)[1]].space
        return DEFAULT_SPACE

    def readers(self, space: str) -> list[str]:
        """The labels of the behaviours (and ``"arbiter"``) that read ``space``, in order."""
        out = [lb for lb, b in self.behaviours.items() if b.space == space]
        return out + (["arbiter"] if self.arbiter.space == space else [])

    def world_key(self, name: str) -> str:
        """The config key that names world ``name`` (for messages): ``experiment.world``,
        ``experiment.rooms[j]``, ``collect.worlds[j]``, a plugin table's ``worlds[j]`` (e.g.
        ``evaluate.worlds[j]``), else ``worlds``."""
        e = self.experiment
        if name == e.world:
            return "experiment.world"
        lists = [("experiment.rooms", e.rooms), ("experiment.validation_rooms",
                                                  e.validation_rooms)]
        if "collect" in e.stages:
            lists.append(("collect.worlds", self.collect.worlds))
        lists += [(f"{t}.worlds", body["worlds"]) for t, body in self.tables.items()
                  if isinstance(body, dict) and isinstance(body.get("worlds"), list)]
        for key, names in lists:
            if name in names:
                return f"{key}[{list(names).index(name)}]"
        return "worlds"

    def worlds(self) -> list[str]:
        """The worlds the core's tables name, once each: the learning world, then the
        collection rooms (if it collects); the evaluation protocols' worlds are their tables'
        (:meth:`sitframe.contract.resolve.Resolved.stage_worlds`)."""
        e = self.experiment
        names = [e.world, *e.rooms, *e.validation_rooms]
        if "collect" in e.stages:
            names += self.collect.worlds
        return list(dict.fromkeys(names))


def list_presets() -> list[str]:
    """Names of the experiment presets shipped with sitframe."""
    root = importlib.resources.files("sitframe.presets")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def preset_text(name: str) -> str:
    """TOML text of a shipped preset."""
    return (importlib.resources.files("sitframe.presets") / f"{name}.toml").read_text("utf-8")


def load_config(experiment: str, *, plugin_folders: bool = False
                ) -> tuple[dict[str, Any], str, str]:
    """Load a preset name or a TOML path.

    ``plugin_folders``: plugins will also be loaded from folders (``--plugins-dir``), so a
    table no installed plugin declares is left for the run to check
    (:func:`complete_tables`); a config's own ``[plugins] dirs`` do the same.

    Returns
    -------
    (config, source, base_dir)
        The validated config (defaults filled in), a label for the source used
        in error messages, and the folder relative paths are resolved from.
    """
    path = Path(experiment)
    try:
        experiment.encode("utf-8")
    except UnicodeEncodeError:
        raise InputError("the file name is not UTF-8; the log stores it as UTF-8 text: rename "
                         "the file", file=experiment) from None
    if experiment.endswith(".toml") or path.exists() or "/" in experiment:
        if not path.is_file():
            raise InputError("config file not found (expected a preset name or a .toml file)",
                             file=experiment)
        try:
            text = path.read_text("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read config: {exc}", file=experiment) from None
        return parse_config(text, file=str(path), pending=plugin_folders), str(path), \
            str(path.parent)
    presets = list_presets()
    if experiment not in presets:
        raise InputError(
            f"unknown experiment '{experiment}'{did_you_mean(experiment, presets)}; "
            f"available presets: {', '.join(presets)} (or give a path to a .toml config)"
        )
    return parse_config(preset_text(experiment), file=f"preset:{experiment}"), \
        f"preset:{experiment}", "."


def parse_config(text: str, *, file: str | None = None, pending: bool = False
                 ) -> dict[str, Any]:
    """Parse and validate config TOML text; fill in defaults (``pending``:
    :func:`validate_config`)."""
    if not text.strip():
        raise InputError("config is empty (expected TOML with at least [behaviours])", file=file)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        twice = re.match(r"Cannot declare \('spaces', '([^']*)'\) twice \((.*)\)", str(exc))
        if twice:  # (two situation spaces with one name: say which, and what a space needs)
            raise InputError(f"two [spaces.{twice.group(1)}] tables ({twice.group(2)}); "
                             "expected one table per space, each space with a name of its own",
                             file=file, key=f"spaces.{twice.group(1)}") from None
        raise InputError(f"not valid TOML: {exc}", file=file) from None
    return validate_config(raw, file=file, pending=pending)


def validate_config(raw: dict[str, Any], *, file: str | None = None,
                    tables: PluginTables | None = None, pending: bool = False
                    ) -> dict[str, Any]:
    """Validate a config dict and return a new dict with defaults filled in.

    Parameters
    ----------
    raw
        The config as parsed.
    file
        Named in every error.
    tables
        The plugins' declared tables (:func:`~sitframe.contract.tables.plugin_tables`);
        default: those of the installed (entry-point) plugins.
    pending
        Keep a table no plugin of ``tables`` declares as it is, for the run to check once
        it has loaded its plugin folders (:func:`complete_tables`); else it is an unknown
        section. Also a config whose ``[plugins] dirs`` name folders keeps them.
    """
    index = installed_tables() if tables is None else tables
    pending = pending or bool((raw.get("plugins") or {}).get("dirs")
                              if isinstance(raw.get("plugins"), dict) else False)
    cfg = copy.deepcopy(DEFAULTS)
    sections = {*DEFAULTS, *OPTIONAL_SECTIONS}
    plugin_tables_given: dict[str, Any] = {}
    for section, value in raw.items():
        if section not in sections and not isinstance(value, dict):
            raise InputError(f"expected a table, got {type(value).__name__}", file=file,
                             key=section)
        if section not in sections:
            if section not in index.tables and not pending:
                raise unknown_table(section, index, file=file)
            plugin_tables_given[section] = value
            continue
        if not isinstance(value, dict):
            raise InputError(f"expected a table, got {type(value).__name__}", file=file,
                             key=section)
        if section == "behaviours":
            cfg["behaviours"] = _validate_behaviours(value, file)
        elif section in _COMPONENT_SECTIONS:
            table = dict(value)
            if "component" in table:
                table["component"] = _at(P.string, "component", table["component"], file, section)
            else:
                table["component"] = DEFAULTS[section]["component"]
            _check_meta(table, file, section, ("reward", "reward_params", "space")
                        if section == "arbiter" else ())
            cfg[section] = table
        elif section == "robot":
            cfg["robot"] = _validate_robot(value, file)
        elif section == "prerequisites":
            cfg[section] = {log: _at(P.string, log, run, file, section)
                            for log, run in value.items()}
        elif section == "spaces":
            cfg[section] = _validate_spaces(value, file)
        else:
            P.known_keys(value, sorted(_CORE_KEYS[section]), prefix=section, file=file)
            cfg[section].update(value)
    _check_core(cfg, file)
    if not cfg["behaviours"]:
        raise InputError("no behaviours configured (expected at least one [behaviours.LABEL] "
                         "table with a 'component')", file=file, key="behaviours")
    cfg = _with_plugin_tables(cfg, plugin_tables_given, index, file)
    _check_space_names(cfg, file)
    _check_utf8(cfg, file, "")
    return cfg


def installed_tables() -> PluginTables:
    """The tables the installed (entry-point) plugins declare (read once per process and
    setting of ``SITFRAME_DISABLE_PLUGIN_AUTOLOAD``; bad declarations are found by the run)."""
    return _installed_tables(bool(os.environ.get(DISABLE_AUTOLOAD_ENV)))


@functools.cache
def _installed_tables(disabled: bool) -> PluginTables:
    if disabled:
        return PluginTables()
    return plugin_tables(Registry.collect(get_plugin_manager(autoload=True), strict=False),
                         strict=False)


def _with_plugin_tables(cfg: dict[str, Any], given: dict[str, Any], index: PluginTables,
                        file: str | None) -> dict[str, Any]:
    """``cfg`` with the plugins' tables: those given (checked against their declarations,
    defaults filled; a table no plugin of ``index`` declares kept as given), those the
    config's components use and those declared ``always`` (their defaults), in order."""
    tables = {name: index.tables[name].validate(value, file=file) if name in index.tables
              else copy.deepcopy(value) for name, value in given.items()}
    for name in [*index.used(cfg, DEFAULT_PROTOCOL),
                 *(n for n, t in index.tables.items() if t.always)]:
        if name not in tables:
            tables[name] = index.tables[name].validate({}, file=file)
    out = {k: cfg[k] for k in _BEFORE_PLUGIN_TABLES if k in cfg}
    out |= {name: tables[name] for name in sorted(tables)}
    out |= {k: v for k, v in cfg.items() if k not in out}
    return out


def complete_tables(cfg: dict[str, Any], index: PluginTables, *,
                    file: str | None = None) -> None:
    """Check ``cfg``'s plugin tables against every plugin's declaration, ``index`` (those
    of plugin folders too), and fill in those its components use: in place, before the
    run's config is written. A table no plugin declares is an unknown section."""
    given = {k: v for k, v in cfg.items() if k not in DEFAULTS and k not in OPTIONAL_SECTIONS}
    for name in given:
        if name not in index.tables:
            raise unknown_table(name, index, file=file)
    done = _with_plugin_tables({k: v for k, v in cfg.items() if k not in given}, given,
                               index, file)
    cfg.clear()
    cfg.update(done)


def _component_table(name: str, table: Any, what: str, component: str, file: str | None,
                     key: str) -> dict[str, Any]:
    """A copy of the table ``[...NAME]`` after checking that ``name`` (a ``what``) can name an
    HDF5 group and that the table names its ``component`` (described for the error)."""
    if name in ("", ".") or "/" in name:
        raise InputError(f"expected a {what} that can name an HDF5 group (not empty, not '.', "
                         f"no '/'), got {name!r}", file=file, key=key)
    if not isinstance(table, dict):
        raise InputError(f"expected a table, got {type(table).__name__}", file=file, key=key)
    if "component" not in table:
        raise InputError(f"missing 'component' ({component})", file=file, key=key)
    _at(P.string, "component", table["component"], file, key)
    return dict(table)


def _validate_spaces(value: dict[str, Any], file: str | None) -> dict[str, Any]:
    """The ``[spaces.NAME]`` tables: names, reserved keys (the interpreter's own parameters
    are checked when the run resolves it, the ``view`` against the sensor's readings)."""
    out = {}
    for name, table in value.items():
        key = f"spaces.{name}"
        if name == DEFAULT_SPACE:
            raise InputError(f"'{DEFAULT_SPACE}' is the name of the [interpreter]'s space; "
                             "expected another name for a space of its own", file=file, key=key)
        t = _component_table(name, table, "space name", "the space's interpreter, e.g. \"fcm\"",
                             file, key)
        if "view" in t:
            view = t["view"]
            if not isinstance(view, list) or not view:
                raise InputError(f"expected a non-empty list of reading indices (0 = the "
                                 f"sensor's first beam), got {view!r}", file=file,
                                 key=f"{key}.view")
            for i, v in enumerate(view):
                _at(P.number, f"view[{i}]", v, file, key, lo=0, integer=True)
            if len(set(view)) != len(view):
                raise InputError(f"names a reading twice in {view}; expected distinct indices",
                                 file=file, key=f"{key}.view")
            t["view"] = [int(v) for v in view]
        if "clusters_from" in t:
            _at(P.string, "clusters_from", t["clusters_from"], file, key)
        if "collect" in t:
            if not isinstance(t["collect"], dict):
                raise InputError("expected a table of [collect] keys", file=file,
                                 key=f"{key}.collect")
            P.known_keys(t["collect"], sorted(_CORE_KEYS["collect"]), prefix=f"{key}.collect",
                         file=file)
        out[name] = t
    return out


def _check_space_names(cfg: dict[str, Any], file: str | None) -> None:
    """Every ``space`` a behaviour or the arbiter names is a space of the config."""
    spaces = [DEFAULT_SPACE, *cfg.get("spaces", {})]
    tables = [(f"behaviours.{lb}", t) for lb, t in cfg["behaviours"].items()]
    for key, table in [*tables, ("arbiter", cfg["arbiter"])]:
        if "space" not in table:
            continue
        name = _at(P.string, "space", table["space"], file, key)
        if name not in spaces:
            raise InputError(f"no situation space '{name}'{did_you_mean(name, spaces)}; the "
                             f"config's spaces are: {', '.join(spaces)} (the [interpreter] is "
                             f"'{DEFAULT_SPACE}', others are [spaces.NAME] tables)", file=file,
                             key=f"{key}.space")


def _check_utf8(value: Any, file: str | None, key: str) -> None:
    """Every key and string below ``value`` is valid UTF-8 (the log stores the config as
    UTF-8 text; a non-UTF-8 file name given on the command line is not)."""
    items = value.items() if isinstance(value, dict) else \
        enumerate(value) if isinstance(value, list) else ()
    for k, v in items:
        sub = f"{key}.{k}" if isinstance(k, str) and key else f"{key}[{k}]" if key else str(k)
        for text in (k, v):
            if isinstance(text, str):
                try:
                    text.encode("utf-8")
                except UnicodeEncodeError:
                    raise InputError("holds bytes that are not UTF-8 (a non-UTF-8 file name?); "
                                     "expected UTF-8 text: rename the file", file=file,
                                     key=sub) from None
        _check_utf8(v, file, sub)


def _at(fn: Any, name: str, value: Any, file: str | None, prefix: str, **kw: Any) -> Any:
    try:
        return fn(name, value, **kw)
    except InputError as exc:
        raise exc.at(file=file, key_prefix=prefix) from None


def _validate_robot(value: dict[str, Any], file: str | None) -> dict[str, Any]:
    P.known_keys(value, sorted(P.accepted_params(RobotParams)[0]), prefix="robot", file=file)
    try:
        RobotParams(**value)
    except InputError as exc:
        raise exc.at(file=file, key_prefix="robot") from None
    except (ValueError, TypeError) as exc:
        raise InputError(str(exc), file=file, key="robot") from None
    return dict(value)


def _check_meta(table: dict[str, Any], file: str | None, key: str,
                takes: tuple[str, ...]) -> None:
    """The reserved keys (:data:`META_KEYS`) of component table ``key``, which ``takes`` some."""
    for k in META_KEYS[1:]:
        if k in table and k not in takes:
            who = "behaviours" if k == "policy_from" else "behaviours and the arbiter"
            raise InputError(f"the {key} table takes no '{k}' (only {who} do)", file=file,
                             key=f"{key}.{k}")
    if "reward" in table:
        _at(P.string, "reward", table["reward"], file, key)
    if "reward_params" in table:
        if not isinstance(table["reward_params"], dict):
            raise InputError("expected a table", file=file, key=f"{key}.reward_params")
        if "reward" not in table:
            raise InputError("reward_params without a reward: name the reward they are for "
                             "(reward = \"...\")", file=file, key=f"{key}.reward_params")


def _validate_behaviours(value: dict[str, Any], file: str | None) -> dict[str, Any]:
    out = {}
    for label, table in value.items():
        key = f"behaviours.{label}"
        t = _component_table(label, table, "behaviour label", "the behaviour's registered name",
                             file, key)
        _check_meta(t, file, key, META_KEYS)
        if "policy_from" in t:
            pf = t["policy_from"]
            if not isinstance(pf, dict) or "log" not in pf:
                raise InputError("expected a table {log = \"path.h5\", trial = 0, "
                                 "behaviour = \"label\"}", file=file, key=f"{key}.policy_from")
            P.known_keys(pf, ("log", "trial", "behaviour"), prefix=f"{key}.policy_from",
                         file=file)
            _at(P.string, "log", pf["log"], file, f"{key}.policy_from")
            if isinstance(pf.get("trial"), dict):
                _check_selection(pf["trial"], file, f"{key}.policy_from.trial")
            elif "trial" in pf and pf["trial"] != "best":
                _at(P.number, "trial", pf["trial"], file, f"{key}.policy_from", lo=0, integer=True)
        out[label] = t
    return out


#: Keys of a ``policy_from.trial`` selection table and their defaults
#: (:func:`sitframe.runs.evaluation.select_trial`), from :data:`SELECTION`.
SELECTION_DEFAULTS: dict[str, Any] = {k.name: "" if k.default is REQUIRED else k.default
                                      for k in SELECTION.keys}


def _check_selection(sel: dict[str, Any], file: str | None, key: str) -> None:
    P.known_keys(sel, list(SELECTION_DEFAULTS), prefix=key, file=file)
    if "world" not in sel:
        raise InputError("expected the world the trials are compared in, e.g. world = "
                         "\"goal-training\"", file=file, key=f"{key}.world")
    sel = {**SELECTION_DEFAULTS, **sel}
    for name in ("world", "score", "episodes", "seed"):
        _at(lambda n, v: SELECTION.key(n).validate(v), name, sel[name], file, key)


#: The order in which :func:`_check_core` checks the core tables' keys (the first wrong key
#: is the one reported).
_CHECK_ORDER = {"experiment": ("name", "description", "seed", "trials", "iterations",
                               "default_speed", "world", "clusters_from", "stages", "rooms",
                               "episode_iterations", "tight_starts", "candidates",
                               "validation_rooms",
                               "validation_iterations"),
                "collect": ("mode", "worlds", "speed", "rate_hz", "wander_samples"),
                "plugins": ("dirs",)}


def _check_core(cfg: dict[str, Any], file: str | None) -> None:
    """Every key of the core tables checked by its declaration (integers stored as int)."""
    for section, names in _CHECK_ORDER.items():
        table, values = _CORE_TABLES[section], cfg[section]
        for name in names:
            if name not in values:  # (a key without default the config leaves out)
                continue
            key = table.key(name)
            checked = _at(lambda _n, v, k=key: k.validate(v), name, values[name], file,
                          section)
            if key.kind == "integer":
                values[name] = checked
    _check_together(cfg["experiment"], file)


def _check_together(e: dict[str, Any], file: str | None) -> None:
    """The ``[experiment]`` keys that need one another (rooms, candidates, validation)."""
    for key, needs, what in (
            ("episode_iterations", "rooms", "the rooms whose episodes last this long"),
            ("tight_starts", "rooms", "the rooms whose episodes start in tight places"),
            ("validation_iterations", "candidates", "the candidates judged this long"),
            ("validation_rooms", "candidates", "the candidates judged there"),
            ("candidates", "validation_rooms", "the rooms the candidates are judged in")):
        if key in e and needs not in e:
            raise InputError(f"expected experiment.{needs} with it ({what})", file=file,
                             key=f"experiment.{key}")
    if "candidates" in e and e["candidates"] > e["iterations"]:
        raise InputError(f"expected at most experiment.iterations ({e['iterations']}) "
                         f"candidates, got {e['candidates']}", file=file,
                         key="experiment.candidates")


def to_toml(cfg: dict[str, Any]) -> str:
    """Render a config dict as TOML (for logs; round-trips through tomllib)."""
    lines: list[str] = []

    def val(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int | float):
            return repr(v)
        if isinstance(v, str):
            return _toml_string(v)
        if isinstance(v, list | tuple):
            return "[" + ", ".join(val(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{_k(k)} = {val(x)}" for k, x in v.items()) + "}"
        raise TypeError(f"cannot render {type(v).__name__} as TOML")

    def table(prefix: str, d: dict[str, Any]) -> None:
        scalars = {k: v for k, v in d.items() if not isinstance(v, dict)}
        nested = {k: v for k, v in d.items() if isinstance(v, dict)}
        if prefix:
            lines.append(f"[{prefix}]")
        for k, v in scalars.items():
            lines.append(f"{_k(k)} = {val(v)}")
        lines.append("")
        for k, v in nested.items():
            if prefix and k in ("reward_params", "policy_from"):
                lines.insert(len(lines) - 1, f"{_k(k)} = {val(v)}")
                continue
            table(f"{prefix}.{_k(k)}" if prefix else _k(k), v)

    table("", cfg)
    return "\n".join(lines).strip() + "\n"


def _k(key: str) -> str:
    """A TOML key: bare if it may be (ASCII letters, digits, ``_``, ``-``), else quoted."""
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _toml_string(key)


def _toml_string(v: str) -> str:
    """A TOML basic string holding exactly ``v`` (control characters escaped)."""
    body = v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
    body = re.sub(r"[\x00-\x08\x0b-\x1f\x7f]", lambda m: f"\\u{ord(m.group()):04x}", body)
    return f'"{body}"'


def config_hash(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
