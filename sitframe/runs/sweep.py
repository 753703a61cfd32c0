"""Run an experiment over a grid of config values and tabulate the results.

``sitframe sweep SWEEP.toml [--workers K | --scheduler ADDRESS] [--out DIR] [--json]``

A sweep file names a base experiment and a grid over dotted config keys::

    [sweep]
    name = "ablation"                  # default: the file's stem
    base = "obstacle-avoidance"        # preset name, or a .toml path relative to this file
    trials = 11                        # shorthand for experiment.trials (trials per point)
    seed = 0                           # shorthand for experiment.seed (same seed at every point)
    out = "logs/sweeps/ablation"       # default logs/sweeps/<name>

    [set]                              # optional: fixed overrides for every point
    "experiment.iterations" = 5000

    [grid]                             # every combination is one grid point
    "behaviours.avoid.update" = ["thesis", "standard"]
    "interpreter.c" = [8, 12, 16]

A component table (``sensor``, ``interpreter``, ``arbiter``,
``behaviours.LABEL``) may also be varied whole, one table per value, to compare
components with different parameters (``sweeps/sensors.toml``)::

    "sensor" = [{ component = "pioneer-sonar", rays_per_beam = 5 }, { component = "laser" }]

Put ``"experiment.seed" = [0, 1, 2]`` in the grid to repeat every point with
several run seeds. Every point keeps the same run seed unless the grid varies
it, so points that differ only in the learner see the same situations and
the same trial seeds (a paired comparison).

Output: one HDF5 log per point, ``DIR/<point>.h5`` (point names such as
``update=thesis_c=8``), and ``DIR/summary.csv`` / ``DIR/summary.md`` with one
row per point: convergence rate, iterations to convergence (median, IQR),
collisions per 1000 iterations after convergence (median, IQR; converged
trials only) and, for every evaluation world, the median, IQR and worst
collisions per 1000, the share of trials above 10, and the median coverage
of the frozen rule bases. When the grid varies ``experiment.seed``,
``DIR/summary-pooled.csv`` / ``.md`` also give one row per setting with the
same statistics over the trials of all its seeds (a result that does not
hang on one seed).

All trials of all points go to one pool (or Dask cluster): the collect and
cluster stages of every point run first as tasks, then the trials (their
evaluations as separate tasks); each point's log is written by this process
in trial order as its trials finish. Results are bit-identical to running
each point with ``sitframe run`` (same seed), whatever the number of workers.

Every key is checked against the base config before anything runs: core
keys against the known sections, component keys against the component's
accepted parameters (:func:`sitframe.params.accepted_params`); the closest
valid key is suggested. Every point's config is then validated and resolved.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import re
import time
import tomllib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sitframe.contract.config import (
    DEFAULTS,
    META_KEYS,
    SPACE_KEYS,
    Component,
    load_config,
    validate_config,
)
from sitframe.contract.tables import plugin_tables
from sitframe.errors import DiskFullError, InputError, did_you_mean, note
from sitframe.params import accepted_params, known_keys
from sitframe.runs.summaries import format_value, summarise_log
from sitframe.sim.robot import RobotParams

# start-up time: this module is imported whenever the command line builds its parser
# (``sitframe --help`` and every command), so what only one command needs is imported
# inside the function that needs it.


_SWEEP_KEYS = ("name", "description", "base", "trials", "seed", "out")
#: Most grid points a sweep may have (each point's experiment is prepared up front).
MAX_POINTS = 10_000


@dataclass
class Point:
    """One grid point: its name, the values it sets and its prepared experiment."""

    name: str
    values: dict[str, Any]
    log: Path
    experiment: Any = None
    run_kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass
class Sweep:
    """A parsed, validated sweep file."""

    name: str
    file: str
    base: str
    base_cfg: dict[str, Any]
    base_source: str
    base_dir: str
    fixed: dict[str, Any]
    grid: dict[str, list[Any]]
    out: Path
    description: str = ""
    points: list[Point] = field(default_factory=list)
    #: Where the output folder came from: ``--out`` (the command line) or ``sweep.out``
    #: (the sweep file, also when it is the default folder).
    out_key: str = "sweep.out"
    plugins_dirs: tuple[str, ...] = ()


# ---------------------------------------------------------------------------
# Parsing and validation
# ---------------------------------------------------------------------------


def load_sweep(path: str, *, out: str | None = None, plugins_dirs: tuple[str, ...] = (),
               prerequisites: Callable[[dict[str, Any], str], Any] | None = None) -> Sweep:
    """Read and validate a sweep file; prepare every grid point's experiment.

    Nothing is written, unless ``prerequisites(base_cfg, base_dir)`` is given: it
    is called before the points are prepared, to make the logs the base config
    builds on (:func:`sitframe.runs.prepare.make_prerequisites`), and after every
    point's config and component parameters were checked, so a bad value in
    the grid is reported before anything is made. Raises
    :class:`InputError` (file, key, suggestion) for anything wrong.
    """
    p = Path(path)
    raw = _read_sweep_file(p, path)
    head = _check_head(raw.get("sweep", {}), path, out)
    name = head.get("name", p.stem)
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.=-]+", name):
        raise InputError(f"expected a name of letters, digits, '_', '-', '.', got {name!r}",
                         file=path, key="sweep.name")
    base_cfg, base_source, base_dir = _load_base(head["base"], p, path, bool(plugins_dirs))
    fixed: dict[str, Any] = dict(raw.get("set", {}))
    for key, short in (("trials", "experiment.trials"), ("seed", "experiment.seed")):
        if key in head:
            fixed[short] = head[key]
    grid = raw.get("grid", {})
    _check_grid(grid, fixed, path)
    plugins = _registry(base_cfg, base_dir, plugins_dirs)
    for where, keys in (("set", fixed), ("grid", grid)):
        for key in keys:
            check_key(key, base_cfg, plugins, file=path, where=where)
    out_dir = Path(out or head.get("out") or Path("logs") / "sweeps" / name)
    if out_dir.exists() and not out_dir.is_dir():
        where = {"file": None, "key": "--out"} if out else {"file": path, "key": "sweep.out"}
        raise InputError(f"'{out_dir}' is a file; expected the folder for the points' logs",
                         **where)
    desc = head.get("description", "")
    sweep = Sweep(name, str(p), head["base"], base_cfg, base_source, base_dir, fixed,
                  dict(grid), out_dir, desc if isinstance(desc, str) else "",
                  out_key="--out" if out else "sweep.out", plugins_dirs=tuple(plugins_dirs))
    _check_points(sweep, plugins)
    if prerequisites is not None:
        prerequisites(base_cfg, base_dir)
    sweep.points = _prepare_points(sweep, plugins_dirs)
    return sweep


def _read_sweep_file(p: Path, path: str) -> dict[str, Any]:
    """The sweep file's TOML, with only the sections ``sweep``, ``set`` and ``grid``."""
    if not p.is_file():
        raise InputError("sweep file not found (expected a .toml sweep definition)", file=path)
    try:
        raw = tomllib.loads(p.read_text("utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read sweep file: {exc}", file=path) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", file=path) from None
    for section in raw:
        if section not in ("sweep", "set", "grid"):
            raise InputError(f"unknown section{did_you_mean(section, ['sweep', 'set', 'grid'])}"
                             "; expected sweep, set, grid", file=path, key=section)
        if not isinstance(raw[section], dict):
            raise InputError("expected a table", file=path, key=section)
    return raw


def _check_head(head: dict[str, Any], path: str, out: str | None) -> dict[str, Any]:
    """The ``[sweep]`` table: known keys, a ``base``, an ``out`` inside the working folder."""
    known_keys(head, _SWEEP_KEYS, prefix="sweep", file=path)
    if "base" not in head:
        raise InputError("missing 'base' (a preset name or the path of an experiment .toml)",
                         file=path, key="sweep.base")
    if not isinstance(head["base"], str) or not head["base"]:
        raise InputError(f"expected a preset name or a path, got {head['base']!r}", file=path,
                         key="sweep.base")
    if "out" in head:
        if not isinstance(head["out"], str) or not head["out"]:
            raise InputError(f"expected a folder path (string), got {head['out']!r}",
                             file=path, key="sweep.out")
        rel = Path(head["out"])
        if out is None and (rel.is_absolute() or ".." in rel.parts):
            raise InputError(f"expected a folder inside the working folder (relative, no '..'), "
                             f"got {head['out']!r}; give --out DIR on the command line to write "
                             "elsewhere", file=path, key="sweep.out")
    return head


def _load_base(base: str, p: Path, path: str, plugin_folders: bool = False
               ) -> tuple[dict[str, Any], str, str]:
    """The base experiment: a preset name, or a .toml path relative to the sweep file."""
    base_arg = base
    if base.endswith(".toml") or "/" in base:
        bp = Path(base)
        base_arg = str(bp if bp.is_absolute() else p.parent / bp)
    try:
        return load_config(base_arg, plugin_folders=plugin_folders)
    except InputError as exc:
        if exc.file in (None, base_arg) and exc.key is None:
            raise InputError(exc.message, file=path, key="sweep.base") from None
        raise


def _check_grid(grid: dict[str, Any], fixed: dict[str, Any], path: str) -> None:
    """Every grid axis a non-empty list of distinct values, not also fixed; not too many
    points; no run names set (a sweep names its points' runs)."""
    if not grid:
        raise InputError("the grid is empty (expected [grid] with at least one "
                         "\"dotted.key\" = [values])", file=path, key="grid")
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise InputError(f"expected a non-empty list of values, got {values!r}", file=path,
                             key=f"grid.{key}")
        if len(set(map(repr, values))) != len(values):
            raise InputError("values repeat (each grid point must be distinct)", file=path,
                             key=f"grid.{key}")
        if key in fixed:
            raise InputError("is both in [grid] and fixed ([set] or [sweep])", file=path,
                             key=f"grid.{key}")
    n_points = math.prod(len(v) for v in grid.values())
    if n_points > MAX_POINTS:
        raise InputError(f"the grid has {n_points} points; expected at most {MAX_POINTS}",
                         file=path, key="grid")
    for where, keys in (("set", fixed), ("grid", grid)):
        if "experiment.name" in keys:
            raise InputError("a sweep names every point's run itself (<sweep name>/<point>); "
                             "expected [sweep] name instead", file=path,
                             key=f"{where}.experiment.name")


def _registry(cfg: dict[str, Any], base_dir: str, plugins_dirs: tuple[str, ...]) -> Any:
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager

    dirs = tuple(d if Path(d).is_absolute() or base_dir in ("", ".") else str(Path(base_dir) / d)
                 for d in cfg["plugins"]["dirs"]) + tuple(plugins_dirs)
    return Registry.collect(get_plugin_manager(plugins_dirs=dirs))


def check_key(key: str, cfg: dict[str, Any], registry: Any, *, file: str | None = None,
              where: str = "grid") -> None:
    """Check that dotted ``key`` names a setting of ``cfg`` (the resolved base config).

    Core sections and plugins' declared tables accept their known keys; component tables (sensor,
    interpreter, arbiter, behaviours.LABEL) accept ``component`` and the
    parameters the component's factory accepts; the arbiter's and a
    behaviour's also the core's keys (reward, reward_params, policy_from)
    and each parameter of their reward (``reward_params.NAME``).

    Raises
    ------
    InputError
        Located at ``<where>.<key>`` in ``file``, with the closest valid key.
    """
    loc = f"{where}.{key}"
    parts = key.split(".")

    def fail(valid: list[str] | set[str], prefix: str, word: str) -> None:
        full = sorted(f"{prefix}{v}" for v in valid)
        hint = did_you_mean(f"{prefix}{word}", full) or did_you_mean(word, sorted(valid))
        raise InputError(f"'{key}' is not a setting of the base experiment{hint}; valid here: "
                         f"{', '.join(full[:12])}{' ...' if len(full) > 12 else ''}",
                         file=file, key=loc)

    def params_of(kind: str, name: str) -> tuple[set[str], bool]:
        entry = registry.entries.get(kind, {}).get(name)
        if entry is None:
            return set(), True
        return accepted_params(entry.factory)

    declared = plugin_tables(registry, strict=False).tables
    sections = [*DEFAULTS, *declared]
    if parts[0] == "spaces" and "spaces" in cfg:  # a situation space of its own
        _check_space_key(parts, cfg["spaces"], fail, params_of)
        return
    if parts[0] not in sections:
        fail(sections, "", parts[0])
    sec = parts[0]
    if key in ("sensor", "interpreter", "arbiter") or (
            sec == "behaviours" and len(parts) == 2 and parts[1] in cfg["behaviours"]):
        return  # a whole component table per value; each point's config is validated
    if sec in ("sensor", "interpreter", "arbiter", "behaviours"):
        _check_component_key(parts, cfg, fail, params_of)
        return
    if sec == "robot":
        valid, _ = accepted_params(RobotParams)
    elif sec in declared:  # a plugin's table: the keys it declares
        valid = {k.name for k in declared[sec].keys}
    else:
        valid = set(DEFAULTS[sec])
    if len(parts) != 2 or parts[1] not in valid:
        fail(valid, f"{sec}.", ".".join(parts[1:]))


def _check_component_key(parts: list[str], cfg: dict[str, Any], fail: Any,
                         params_of: Any) -> None:
    """:func:`check_key` for a key of a component table (sensor, interpreter, arbiter,
    behaviours.LABEL): ``component``, the component's parameters, the core's keys of a
    behaviour or the arbiter, and the parameters of its reward."""
    sec = parts[0]
    if sec == "behaviours":
        labels = list(cfg["behaviours"])
        if len(parts) < 3 or parts[1] not in labels:
            fail([f"{lb}.component" for lb in labels], "behaviours.", ".".join(parts[1:]))
        kind, table, prefix, rest = ("behaviour", cfg["behaviours"][parts[1]],
                                     f"behaviours.{parts[1]}.", parts[2:])
    else:
        kind, table, prefix, rest = sec, cfg[sec], f"{sec}.", parts[1:]
    names, var_kw = params_of(kind, table["component"])
    meta = set(META_KEYS) if kind in ("behaviour", "arbiter") else {"component"}
    if rest[0] == "reward_params" and "reward_params" in meta and len(rest) > 1:
        rnames, rvar = params_of("reward", table.get("reward") or "")
        if len(rest) != 2 or (rest[1] not in rnames and not rvar):
            fail(rnames, f"{prefix}reward_params.", ".".join(rest[1:]))
        return
    if len(rest) != 1 or (rest[0] not in meta | names and not var_kw):
        fail(meta | names, prefix, ".".join(rest))


def _check_space_key(parts: list[str], spaces: dict[str, Any], fail: Any,
                     params_of: Any) -> None:
    """:func:`check_key` for ``spaces.NAME.KEY``: the space's interpreter's parameters and
    the reserved keys of a space table."""
    if len(parts) < 3 or parts[1] not in spaces:
        fail([f"{n}.component" for n in spaces], "spaces.", ".".join(parts[1:]))
    names, var_kw = params_of("interpreter", spaces[parts[1]]["component"])
    valid = names | set(SPACE_KEYS)
    if len(parts) != 3 or (parts[2] not in valid and not var_kw):
        fail(valid, f"spaces.{parts[1]}.", ".".join(parts[2:]))


def _set(cfg: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    d = cfg
    for part in parts[:-1]:
        d = d.setdefault(part, {})
    d[parts[-1]] = copy.deepcopy(value)


def point_names(grid: dict[str, list[Any]], *, file: str | None = None
                ) -> list[tuple[str, dict[str, Any]]]:
    """Every grid combination as ``(name, {key: value})``, in grid order.

    Names use each key's last part (``c=8``) unless two keys share it, then the
    full dotted key; characters unsafe in file names become ``-``. Floats are
    written as short as they read back exactly (``0.1``, ``0.1000001``).

    Raises
    ------
    InputError
        Two points get the same name (also when they differ only in case,
        which a case-insensitive file system would merge), e.g. ``2`` and
        ``2.0``, or ``"rooms/a.toml"`` and ``"rooms-a.toml"``: their logs would
        overwrite each other.
    """
    keys = list(grid)
    last = [k.rsplit(".", 1)[-1] for k in keys]
    short = {k: (s if last.count(s) == 1 else k) for k, s in zip(keys, last, strict=True)}
    out = []
    seen: dict[str, dict[str, Any]] = {}
    for combo in itertools.product(*(grid[k] for k in keys)):
        values = dict(zip(keys, combo, strict=True))
        name = "_".join(f"{short[k]}={format_value(v)}" for k, v in values.items())
        name = re.sub(r"[^A-Za-z0-9_.=+-]", "-", name)
        other = seen.setdefault(name.lower(), values)
        if other is not values:
            a, b = ([f"{k}={other[k]!r}" for k in keys if other[k] != values[k]
                     or type(other[k]) is not type(values[k])],
                    [f"{k}={values[k]!r}" for k in keys if other[k] != values[k]
                     or type(other[k]) is not type(values[k])])
            raise InputError(f"grid points {', '.join(a)} and {', '.join(b)} get the same log "
                             f"name '{name}' (their logs would overwrite each other); expected "
                             "values that differ in their file-name form", file=file, key="grid")
        out.append((name, values))
    return out


def _point_configs(sweep: Sweep) -> Iterator[tuple[str, dict[str, Any], dict[str, Any], str]]:
    """Each point's name, grid values, config (unvalidated) and where its errors point."""
    for name, values in point_names(sweep.grid, file=sweep.file):
        cfg = copy.deepcopy(sweep.base_cfg)
        for key, val in {**sweep.fixed, **values}.items():
            _set(cfg, key, val)
        cfg["experiment"]["name"] = f"{sweep.name}/{name}"
        yield name, values, cfg, f"{sweep.file} (point {name})"


@contextmanager
def _at_point(sweep: Sweep, name: str, where: str) -> Iterator[None]:
    """Report a point's InputError at the sweep file, ``point NAME: key``."""
    try:
        yield
    except InputError as exc:
        if exc.file == where:
            raise InputError(exc.message, file=sweep.file,
                             key=f"point {name}: {exc.key}" if exc.key else
                             f"point {name}") from None
        raise


def _check_points(sweep: Sweep, registry: Any) -> None:
    """Validate every point's config and create its components (their parameters checked),
    cheaply and before any prerequisite run is made."""
    for name, _values, cfg, where in _point_configs(sweep):
        with _at_point(sweep, name, where):
            cfg = validate_config(cfg, file=where, tables=plugin_tables(registry))
            tables = [("sensor", "sensor", cfg["sensor"]),
                      ("interpreter", "interpreter", cfg["interpreter"]),
                      ("arbiter", "arbiter", cfg["arbiter"]),
                      *[("behaviour", f"behaviours.{lb}", t)
                        for lb, t in cfg["behaviours"].items()]]
            for kind, key, table in tables:
                c = Component.of(table)
                registry.create(kind, c.name, c.params, file=where, key=key)
                if c.reward is not None:
                    registry.create("reward", c.reward, c.reward_params, file=where,
                                    key=f"{key}.reward_params")


def _prepare_points(sweep: Sweep, plugins_dirs: tuple[str, ...]) -> list[Point]:
    from sitframe.runs.prepare import prepare_experiment

    points = []
    for name, values, cfg, where in _point_configs(sweep):
        log = sweep.out / f"{name}.h5"
        with _at_point(sweep, name, where):
            cfg = validate_config(cfg, file=where, pending=True)  # (checked as it resolves)
            exp, kwargs = prepare_experiment(cfg, source=where, base_dir=sweep.base_dir,
                                             out=str(log), plugins_dirs=plugins_dirs)
        # Relative paths in the config resolve from the base config's folder
        # (``run --resume`` on a point's log relies on this).
        exp.info.extra["source"] = sweep.base_source
        points.append(Point(name, values, log, exp, kwargs))
    return points


# ---------------------------------------------------------------------------
# Running
# ---------------------------------------------------------------------------


def run_sweep(sweep: Sweep, executor: Any, *, progress: bool = False,
              reuse: bool = False) -> dict[str, Any]:
    """Run every point's stages and trials through ``executor`` (one run lifecycle,
    :func:`sitframe.runs.experiment.drive`, for all points at once).

    Each point's log is written in this process, in trial order, as trials
    finish; this process holds every point log's lock for the whole sweep.
    Ctrl-C (or SIGTERM) cancels pending work, marks unfinished points
    ``aborted`` and re-raises. ``progress`` shows the progress plugin's bar
    over all points' trials. ``reuse`` keeps a point's existing log instead
    of running the point again when the log is complete and was made by the
    point's config (the same config hash, as for a run's prerequisites) and
    by the same code (the log's ``code_hash``: sitframe, its plugins and
    loose plugin files), and says so on stderr. A log of the same config
    made by other code is run again, and said: a grid whose points came
    from two versions of a plugin would compare the versions, not the grid.
    With ``reuse``, an unfinished log of the point's config and code (a sweep
    stopped by Ctrl-C, a kill or a full disk) is finished as ``run --resume``
    finishes it: its finished trials are kept and only the missing ones run.

    A full disk ends the sweep in one :class:`~sitframe.errors.DiskFullError`
    line naming the folder, what is free there and about what finishing every
    point needs; every finished trial stays in the points' logs, and running the
    sweep again with ``--reuse`` in a place with space finishes it.

    Returns
    -------
    dict
        ``{"name", "out", "wall_seconds", "points": [summary row per point],
        "reused": [names of the points whose logs were kept], "finished": [names of the
        points whose unfinished logs were resumed]}``.
    """
    from sitframe.runs.experiment import RunPlan, drive

    t0 = time.perf_counter()
    for pt in sweep.points:  # one writer per log: refuse before any point writes anything
        _claim(sweep, pt)
    codes: dict[str, str] = {}  # (one source fingerprint per plugin list, not per point)
    found = {pt.name: _reusable(pt, codes) for pt in sweep.points} if reuse else {}
    kept = [name for name, how in found.items() if how == "same"]
    if kept:
        note(f"reusing {len(kept)} of {len(sweep.points)} points' logs in {sweep.out} "
             "(complete, made by the same config and code): " + ", ".join(kept))
    stale = [name for name, how in found.items() if how == "code"]
    if stale:
        note(f"not reusing {len(stale)} of {len(sweep.points)} points' logs, complete and of "
             "the same config but made by other code (code hash differs); running them "
             "again: " + ", ".join(stale))
    unfinished = [name for name, how in found.items() if how == "unfinished"]
    if unfinished:
        note(f"finishing {len(unfinished)} of {len(sweep.points)} points' unfinished logs in "
             f"{sweep.out} (same config and code; their finished trials are kept): "
             + ", ".join(unfinished))
    todo = [pt for pt in sweep.points if pt.name not in kept]
    for pt in todo:
        if pt.name in unfinished:
            _resume_point(sweep, pt)
        pt.experiment.info.extra["progress"] = progress
        pt.experiment.info.extra["progress_group"] = f"sweep {sweep.name}"
    try:
        drive([(pt.experiment, RunPlan.of(pt.run_kwargs)) for pt in todo], executor)
    except DiskFullError as exc:
        raise _disk_full(sweep, exc) from None
    except InputError as exc:  # a setting found wrong only as a point ran: say which point
        pt = next((p for p in todo if p.experiment.res.file == exc.file), None)
        if pt is None:
            raise
        with _at_point(sweep, pt.name, exc.file):
            raise
    rows = [{"point": pt.name, **pt.values, **summarise_log(pt.log)} for pt in sweep.points]
    return {"name": sweep.name, "out": str(sweep.out), "keys": list(sweep.grid),
            "wall_seconds": round(time.perf_counter() - t0, 3), "points": rows,
            "reused": kept, "finished": unfinished}


def _claim(sweep: Sweep, pt: Point) -> None:
    """Become the writer of a point's log (refused, naming where the folder came from)."""
    from sitframe.logs.writer import lock_log

    try:
        lock_log(pt.log, key=sweep.out_key)
    except InputError as exc:
        if sweep.out_key == "--out":
            raise
        raise InputError(f"{pt.log}: {exc.message}", file=sweep.file, key="sweep.out") from None


def _resume_point(sweep: Sweep, pt: Point) -> None:
    """Make the point finish its unfinished log (as ``run --resume``) instead of rerunning it."""
    from sitframe.runs.prepare import prepare_resume

    exp, kwargs, _missing = prepare_resume(pt.log, plugins_dirs=sweep.plugins_dirs)
    exp.info.extra["source"] = sweep.base_source
    pt.experiment, pt.run_kwargs = exp, kwargs


def _disk_full(sweep: Sweep, exc: DiskFullError) -> DiskFullError:
    """The sweep's one line for a full disk: what finishing every point needs, and how."""
    from sitframe.logs.writer import human_size, space_to_finish

    need = space_to_finish([(pt.log, pt.experiment.info.n_trials) for pt in sweep.points])
    again = f"sitframe sweep {sweep.file}" + (f" --out {sweep.out}"
                                              if sweep.out_key == "--out" else "")
    return DiskFullError(
        f"the disk is full: {exc.folder} has {human_size(exc.free)} free and finishing the "
        f"sweep needs about {human_size(need)} more (writing {exc.file} failed); every "
        f"finished trial is kept: make space there and run `{again} --reuse`, which keeps "
        "the complete points' logs and finishes the others", file=sweep.file, folder=exc.folder,
        free=exc.free)


def _reusable(pt: Point, codes: dict[str, str]) -> str:
    """``"same"`` if the point's log is complete and was made by the point's config and this
    code, ``"code"`` if only the code differs, else ``""``. ``codes`` caches the code
    fingerprint by plugin list."""
    from sitframe.logs.reader import open_log
    from sitframe.logs.writer import code_fingerprint

    if not pt.log.exists():
        return ""
    try:
        log = open_log(pt.log)
    except InputError:
        return ""  # (not a readable log: the run replaces it or refuses, as without reuse)
    if str(log.attrs.get("config_hash", "")) != pt.experiment.info.config_hash:
        return ""
    info = pt.experiment.info
    key = json.dumps(info.plugins, sort_keys=True)
    if key not in codes:
        codes[key] = code_fingerprint(info.plugins)
    code = info.extra.setdefault("code_hash", codes[key])
    same = str(log.attrs.get("code_hash", "")) == code
    if not log.complete:
        return "unfinished" if same else ""
    return "same" if same else "code"


__all__ = ["Sweep", "check_key", "load_sweep", "point_names", "run_sweep"]
