"""Reading a log: :func:`open_log`, :class:`Log` and :class:`TrialLog`.

The reader never blocks the writer, follows a trial's external link only to the trial file
beside the log, and checks the parts of the layout it indexes with, so that a damaged log is
one :class:`~sitframe.errors.InputError` naming the item. The layout is in
:mod:`sitframe.logs.layout`.
"""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import h5py
import numpy as np

from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.records import (
    LearnedPolicy,
    PolicyOutput,
    SensorSpec,
)
from sitframe.errors import InputError
from sitframe.logs.interrupts import deferred_interrupt
from sitframe.logs.layout import (
    READING,
    SCHEMA,
    SCHEMA_VERSION,
    TRIAL_GROUPS,
    shard_file,
)


def _read_group(g: h5py.Group) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in g.attrs.items():
        out[k] = _attr(v)
    for k, item in g.items():
        if isinstance(item, h5py.Group):
            for kk, vv in _read_group(item).items():
                out[f"{k}/{kk}"] = vv
        else:
            out[k] = item[()]
    return out


def _attr(v: Any) -> Any:
    if isinstance(v, bytes):
        v = v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


@dataclass
class TrialLog:
    """One trial read back from a log.

    Attributes
    ----------
    index, seed, world
        Trial number, 64-bit seed, world name.
    summary
        Summary scalars (``converged``, ``convergence_iteration``, ...).
    arrays
        Per-iteration arrays (see the module docstring for names and units).
    behaviours
        Behaviour label -> flattened dict of its logged data.
    episodes
        Evaluation / goal-episode arrays.
    plugins
        Plugin name -> flattened dict of the data it handed for the trial.
    situations
        With an evolving interpreter: flattened ``state/...``, ``events/...`` and
        ``count`` of the trial's situations (empty otherwise).
    """

    index: int
    seed: int
    world: str
    summary: dict[str, Any]
    arrays: dict[str, np.ndarray]
    behaviours: dict[str, dict[str, Any]]
    episodes: dict[str, Any] = field(default_factory=dict)
    plugins: dict[str, dict[str, Any]] = field(default_factory=dict)
    situations: dict[str, Any] = field(default_factory=dict)

    def situations_part(self, part: str) -> dict[str, Any]:
        """``"state"`` (the trial's final interpreter state) or ``"events"`` of
        :attr:`situations`, unflattened one level; empty for a fixed interpreter."""
        head = f"{part}/"
        return {k[len(head):]: v for k, v in self.situations.items() if k.startswith(head)}

    def policy(self, label: str) -> dict[str, np.ndarray]:
        """The learned rule bases (``output -> (c,) action indices``) of behaviour ``label``.

        Raises
        ------
        ValueError
            The trial has no behaviour ``label`` (the message lists those it has).
        """
        if label not in self.behaviours:
            raise ValueError(f"trial {self.index} has no behaviour '{label}'; it has: "
                             f"{', '.join(self.behaviours) or 'none'}")
        data = self.behaviours[label]
        return {k.split("/", 1)[1]: np.asarray(v) for k, v in data.items()
                if k.startswith("policy/")}

    def learned_policy(self, label: str) -> LearnedPolicy | None:
        """The :class:`LearnedPolicy` of behaviour ``label`` (``None`` if it learned none).

        Logs written before contract v2 kept the action values under
        ``singletons/<output>``; they are read the same way. A label the trial
        does not have is a ``ValueError`` (:meth:`policy`), not ``None``.
        """
        data = self.behaviours.get(label, {})
        outs = {}
        for out, rules in self.policy(label).items():
            actions = data.get(f"actions/{out}", data.get(f"singletons/{out}"))
            if actions is None:
                continue
            q = data.get(f"q/{out}", data.get(f"{out}/q"))
            unit = data.get(f"units/{out}", _OLD_UNITS.get(out, ""))
            try:
                outs[out] = PolicyOutput(np.asarray(actions), np.asarray(rules), str(unit),
                                         None if q is None else np.asarray(q))
            except (TypeError, ValueError) as exc:
                raise InputError(f"the logged policy of trial {self.index} is damaged: {exc}",
                                 key=f"trials/{self.index:04d}/behaviours/{label}/policy/{out}"
                                 ) from None
        return LearnedPolicy(outs) if outs else None

    @cached_property
    def policies(self) -> dict[str, LearnedPolicy]:
        """Label -> :class:`LearnedPolicy` of every behaviour that learned one."""
        out = {}
        for label in self.behaviours:
            pol = self.learned_policy(label)
            if pol is not None:
                out[label] = pol
        return out


#: Units of the built-in outputs in logs written before units were logged.
_OLD_UNITS = {"heading": "deg", "speed": "m/s"}


@dataclass
class Log:
    """A sitframe HDF5 log opened for reading (the file is not kept open).

    Use :func:`open_log`. Attributes mirror the root attributes; methods read
    stages and trials on demand.
    """

    path: str
    attrs: dict[str, Any]

    @property
    def status(self) -> str:
        return str(self.attrs.get("status", "unknown"))

    @property
    def complete(self) -> bool:
        return self.status == "complete"

    @property
    def learned(self) -> bool:
        """Whether the logged run had a ``learn`` stage (True when its config does not say)."""
        return "learn" in self.config.get("experiment", {}).get("stages", ["learn"])

    @property
    def config(self) -> dict[str, Any]:
        text = self.attrs.get("config")
        if not isinstance(text, str):
            raise InputError("the log has no config (expected the run's TOML in the root "
                             "attribute 'config')", file=self.path, key="config")
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"the log's config is not valid TOML: {exc}", file=self.path,
                             key="config") from None

    def _json_attr(self, name: str, default: str, kind: type) -> Any:
        try:
            value = json.loads(self.attrs.get(name, default))
        except (TypeError, ValueError) as exc:
            raise InputError(f"root attribute is not valid JSON: {exc}", file=self.path,
                             key=name) from None
        if not isinstance(value, kind):
            raise InputError(f"root attribute should hold a JSON {kind.__name__}, got "
                             f"{type(value).__name__}", file=self.path, key=name)
        return value

    @property
    def worlds(self) -> dict[str, str]:
        return self._json_attr("worlds", "{}", dict)

    @property
    def plugins(self) -> list[dict[str, Any]]:
        return self._json_attr("plugins", "[]", list)

    @property
    def versions(self) -> dict[str, str]:
        return self._json_attr("versions", "{}", dict)

    @property
    def failure(self) -> str | None:
        """The one-line reason the run failed (plugin code), if it did."""
        v = self.attrs.get("failure")
        return str(v) if v else None

    @cached_property  # (read once: an old log's asks the plugin registry)
    def sensor(self) -> SensorSpec:
        """The run sensor's geometry (name, beam angles, max range).

        Logs written before the spec was logged: the spec of the sensor plugin
        the ``[sensor]`` table names, created with the table's parameters.
        """
        d = self._json_attr("sensor", "{}", dict) or self._sensor_from_config()
        try:
            return SensorSpec(str(d["name"]), np.asarray(d["angles_deg"], dtype=np.float64),
                              float(d["max_range"]), str(d.get("unit", "m")))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"root attribute is not a sensor spec: {exc}", file=self.path,
                             key="sensor") from None

    def _sensor_from_config(self) -> dict[str, Any]:
        table = dict(self.config.get("sensor", {}))
        name = str(table.pop("component", "pioneer-sonar"))
        registry = Registry.collect(get_plugin_manager())
        sensor = registry.create("sensor", name, table, file=self.path, key="sensor")
        return {"name": name, "angles_deg": np.asarray(sensor.angles_deg).tolist(),
                "max_range": sensor.max_range}

    @contextmanager
    def _file(self) -> Iterator[h5py.File]:
        """Open the log read-only; a damaged file or a missing item becomes an InputError."""
        try:
            with deferred_interrupt(), h5py.File(self.path, "r") as f:
                yield f
        except InputError:
            raise
        except (OSError, KeyError, RuntimeError, ValueError, TypeError) as exc:
            msg = " ".join(str(exc.args[0] if exc.args else exc).split())
            raise InputError(f"cannot read the log (truncated or corrupted?): {msg}",
                             file=self.path) from None

    def check(self) -> None:
        """Read the whole log: every header, attribute and dataset, and the root JSON.

        Also checks the layout every reader relies on (:func:`_check_layout`).
        Raises an :class:`InputError` naming the log if any part is damaged, so
        a command can fail before it writes anything. Datasets carry Fletcher-32
        checksums (logs written since they were added), so damaged *data* is
        caught here too, not only damaged structure.
        """
        _ = self.worlds, self.plugins, self.versions
        def read(_name: str, obj: Any) -> None:  # (returning a value would stop the visit)
            dict(obj.attrs)
            if isinstance(obj, h5py.Dataset):
                obj[()]

        with self._file() as f:
            f.visititems(read)  # hard links only: the trials in their own files are read below
            _check_layout(f, self.path)
            for name in _trial_names(f, self.path):
                g = _trial_group(f, name, self.path)
                if g is not None and g.file != f:
                    dict(g.attrs)
                    g.visititems(read)

    def has(self, group: str) -> bool:
        with self._file() as f:
            return group in f

    def trial_indices(self) -> list[int]:
        with self._file() as f:
            out = []
            for name in _trial_names(f, self.path):
                link = f["trials"].get(name, getlink=True)
                if isinstance(link, h5py.ExternalLink):  # checked: NNNN.h5 for trial NNNN
                    shard_file(self.path, name, link)
                    out.append(int(name))
                else:
                    out.append(int(f["trials"][name].attrs["index"]))
            return sorted(out)

    def stage(self, name: str) -> dict[str, Any]:
        """Flattened dict of a stage group (``collect`` or ``cluster``)."""
        with self._file() as f:
            if name not in f:
                raise InputError(f"the log has no '{name}' stage (status: {self.status})",
                                 file=self.path, key=name)
            return _read_group(f[name])

    def interpreter_state(self) -> dict[str, Any]:
        """The fitted interpreter state written by the cluster stage."""
        with self._file() as f:
            if "cluster/state" not in f:
                raise InputError("the log has no fitted situations (no /cluster/state); "
                                 "was the cluster stage run?", file=self.path, key="cluster")
            return _read_group(f["cluster/state"])

    def space_names(self) -> list[str]:
        """The situation spaces of their own the run had (``/spaces/NAME``), in config order;
        empty for a run with one space."""
        with self._file() as f:
            if "spaces" not in f:
                return []
            names = list(f["spaces"])
        order = list(self.config.get("spaces", {}))
        return sorted(names, key=lambda n: (order.index(n) if n in order else len(order), n))

    def space(self, name: str) -> dict[str, Any]:
        """Space ``name`` as logged: ``view``, ``readers``, ``labels``, ``component``,
        ``source`` and ``state`` (its fitted state, as :meth:`interpreter_state`), plus
        ``fit`` when it was fitted in the run and ``samples`` when on data of its own."""
        with self._file() as f:
            if f"spaces/{name}/state" not in f:
                have = list(f["spaces"]) if "spaces" in f else []
                raise InputError(f"the log has no situation space '{name}' (it has "
                                 f"{', '.join(['default', *have])})", file=self.path,
                                 key=f"spaces/{name}")
            g = f[f"spaces/{name}"]
            out: dict[str, Any] = {k: _attr(v) for k, v in g.attrs.items()}
            for k in ("readers", "labels"):
                if isinstance(out.get(k), str):
                    out[k] = json.loads(out[k])
            out["view"] = None
            for k, item in g.items():  # view, samples (its own data), state, fit
                out[k] = _read_group(item) if isinstance(item, h5py.Group) else item[()]
            return out

    def space_states(self) -> dict[str, dict[str, Any]]:
        """Name -> fitted state of every situation space of its own (empty: one space)."""
        return {name: self.space(name)["state"] for name in self.space_names()}

    def trial(self, index: int) -> TrialLog:
        """Read trial ``index`` (an InputError lists the trials present if it is missing)."""
        with self._file() as f:
            _trial_names(f, self.path)
            g = _trial_group(f, f"{index:04d}", self.path)
            if g is None:
                have = self.trial_indices()
                raise InputError(f"the log has no trial {index}; it has "
                                 f"{have if have else 'no finished trials'}",
                                 file=self.path, key="trials")
            arrays = {}
            for k, item in g.items():
                if k in TRIAL_GROUPS:
                    continue
                if isinstance(item, h5py.Group):
                    arrays.update({f"{k}/{kk}": v for kk, v in _read_group(item).items()
                                   if isinstance(v, np.ndarray)})
                else:
                    arrays[k] = item[()]
            if READING not in arrays and "sonar" in arrays:  # a log from before contract v2
                arrays[READING] = arrays["sonar"]
            if READING in arrays:  # the name the README showed before contract v2
                arrays.setdefault("sonar", arrays[READING])
            behaviours = ({lb: _read_group(bg) for lb, bg in g["behaviours"].items()}
                          if "behaviours" in g else {})
            episodes = _read_group(g["episodes"]) if "episodes" in g else {}
            plugins = ({p: _read_group(pg) for p, pg in g["plugins"].items()}
                       if "plugins" in g else {})
            summary = dict(_read_group(g["summary"])) if "summary" in g else {}
            summary = {k.replace(".", "/"): v for k, v in summary.items()}
            situations = _read_group(g["situations"]) if "situations" in g else {}
            return TrialLog(int(g.attrs["index"]), int(g.attrs["seed"]), str(g.attrs["world"]),
                            summary, arrays, behaviours, episodes, plugins, situations)

    def summary(self, *, plugins: bool = False) -> np.ndarray:
        """The root summary table (structured array, one row per finished trial).

        With ``plugins=True`` (what ``sitframe export``, ``sitframe compare`` and
        :meth:`summary_frame` read), every per-trial scalar a plugin logged follows as a
        column of its own (:meth:`plugin_scalars`: ``plugins.<plugin>.<key>``,
        ``behaviours.<label>.<key>``), restricted to the trials whose group is in the log;
        a column is ``bool`` (``int64``) when every trial logged a bool (an integer), else
        ``float64`` with NaN where a trial logged none. The log's own table is not changed:
        the columns are read from the trial groups.
        """
        with self._file() as f:
            table = f["summary"][()] if "summary" in f else np.zeros(0, dtype=[("trial", "i4")])
        if not plugins:
            return table
        extra = self.plugin_scalars()
        if table.size:
            table = table[np.isin(table["trial"], sorted(extra))]
        rows = [extra.get(int(k), {}) for k in table["trial"]]
        return _with_columns(table, rows)

    def plugin_scalars(self) -> dict[int, dict[str, bool | int | float]]:
        """Trial index -> every per-trial scalar its plugins logged, by namespaced name.

        ``plugins.<plugin>.<key>`` for what a plugin's components returned from
        ``trial_end`` and its observers from ``sitframe_trial_data``
        (``/trials/NNNN/plugins/<plugin>/<key>``; an evaluation's as
        ``plugins.<plugin>.eval.<world>.<key>``), ``behaviours.<label>.<key>`` for what a
        behaviour (or the learning arbiter, label ``arbiter``) returned from
        ``trial_data``: the log's path below the trial with ``/`` as ``.``. Scalars are
        numbers and bools (strings and arrays are not); arrays are in
        :attr:`TrialLog.plugins` and :attr:`TrialLog.behaviours`. Read from the groups'
        attributes only, so it is quick for any length of trial.
        """
        out: dict[int, dict[str, bool | int | float]] = {}
        with self._file() as f:
            for name in _trial_names(f, self.path):
                g = _trial_group(f, name, self.path)
                if not isinstance(g, h5py.Group):
                    continue
                row: dict[str, bool | int | float] = {}
                for part in ("plugins", "behaviours"):
                    if isinstance(g.get(part), h5py.Group):
                        _scalars(g[part], part, row)
                out[int(g.attrs.get("index", int(name)))] = row
        return out

    def weight_labels(self, index: int) -> list[str] | None:
        """The behaviour labels of trial ``index``'s ``weights`` columns (None: not named)."""
        with self._file() as f:
            ds = f.get(f"trials/{index:04d}/weights")
            raw = ds.attrs.get("columns") if ds is not None else None
        try:
            return list(json.loads(raw)) if raw is not None else None
        except (TypeError, ValueError):
            return None

    def summary_frame(self) -> Any:
        """The summary table as a pandas DataFrame (needs pandas; see
        :func:`sitframe.logs.frames.summary_frame`)."""
        from sitframe.logs.frames import summary_frame  # pandas is optional: loaded on use

        return summary_frame(self)

    def iterations_frame(self, trials: list[int] | None = None) -> Any:
        """Per-iteration arrays of the learning trials as one pandas DataFrame (needs pandas;
        see :func:`sitframe.logs.frames.iterations_frame`)."""
        from sitframe.logs.frames import iterations_frame  # pandas is optional: loaded on use

        return iterations_frame(self, trials)


def _scalars(g: h5py.Group, prefix: str, out: dict[str, bool | int | float]) -> None:
    """The numeric and bool attributes below ``g`` into ``out``, as ``prefix.<path>``."""
    for k, v in g.attrs.items():
        v = _attr(v)
        if isinstance(v, bool | int | float):
            out[f"{prefix}.{k}"] = v
    for k, item in g.items():
        if isinstance(item, h5py.Group):
            _scalars(item, f"{prefix}.{k}", out)


def _with_columns(table: np.ndarray, rows: list[dict[str, bool | int | float]]) -> np.ndarray:
    """``table`` with one more column per key of ``rows`` (one row per table row): ``bool``
    (``int64``) where every row holds a bool (an integer), else ``float64`` (NaN where a row
    holds none)."""
    have = set(table.dtype.names or ())
    keys = [k for k in dict.fromkeys(k for r in rows for k in r) if k not in have]
    if not keys:
        return table
    kinds = {k: "?" if all(isinstance(r.get(k), bool) for r in rows) else "i8" if all(
        isinstance(r.get(k), int) and not isinstance(r.get(k), bool) for r in rows) else "f8"
        for k in keys}
    base = [(n, table.dtype[n]) for n in table.dtype.names or ()]
    out = np.zeros(table.size, dtype=base + [(k, kinds[k]) for k in keys])
    for name in table.dtype.names or ():
        out[name] = table[name]
    for k in keys:
        out[k] = [r[k] if kinds[k] != "f8" else float(r.get(k, np.nan)) for r in rows]
    return out


def _trial_names(f: h5py.File, path: str) -> list[str]:
    """The names in ``/trials`` (none if absent; an InputError if it is not a group)."""
    trials = f.get("trials")
    if trials is None:
        return []
    if not isinstance(trials, h5py.Group):
        raise InputError("expected a group of trial groups, got a dataset", file=path,
                         key="trials")
    return list(trials)


def _trial_group(f: h5py.File, name: str, path: str) -> h5py.Group | h5py.Dataset | None:
    """``/trials/<name>`` (None if absent), following its link only if it is a trial file of
    the log (:func:`shard_file`): a log never makes the reader open another file."""
    trials = f["trials"]
    link = trials.get(name, getlink=True)
    if link is None:
        return None
    if isinstance(link, h5py.SoftLink):
        raise InputError(f"is a soft link to '{link.path}'; expected a trial group",
                         file=path, key=f"trials/{name}")
    if isinstance(link, h5py.ExternalLink):
        shard_file(path, name, link)
    return trials[name]


def _check_layout(f: h5py.File, path: str) -> None:
    """The parts of the layout that readers index with, checked so that a valid HDF5 file
    with damaged contents is one clear :class:`InputError` (naming the item), not a wrong
    figure or a traceback: ``/trials`` holds trial groups, fitted centres are a finite
    (c, d) array matching the trials' memberships (c) and readings (d), and every learned
    policy indexes an existing action."""
    def fail(key: str, what: str) -> None:
        raise InputError(what, file=path, key=key)

    trials = f.get("trials")
    if trials is not None and not isinstance(trials, h5py.Group):
        fail("trials", "expected a group of trial groups, got a dataset")
    centers = f.get("cluster/state/centers")
    shape = None
    if centers is not None:
        c = np.asarray(centers[()])
        if c.ndim != 2 or c.dtype.kind not in "fiu" or not np.isfinite(c).all():
            fail("cluster/state/centers", f"expected a finite (c, d) array of centres, got "
                 f"shape {c.shape}, dtype {c.dtype}")
        shape = c.shape
        capacity = f["cluster/state"].attrs.get("capacity")  # evolving situations: id slots
        if capacity is not None:
            shape = (int(capacity), shape[1])
    for name in _trial_names(f, path):
        _check_trial_layout(f, name, shape, path)


def _check_trial_layout(f: h5py.File, name: str, shape: tuple[int, int] | None,
                        path: str) -> None:
    """One trial of :func:`_check_layout`: its group, the shapes of its readings and
    memberships against the centres' ``shape``, and its policies' action indices."""
    def fail(key: str, what: str) -> None:
        raise InputError(what, file=path, key=key)

    g = _trial_group(f, name, path)
    if not isinstance(g, h5py.Group):
        fail(f"trials/{name}", "expected a trial group, got a dataset")
    if g.file != f and g.attrs.get("index") != int(name):
        fail(f"trials/{name}", f"its file holds trial {_attr(g.attrs.get('index'))!r}, expected "
             f"{int(name)}")
    for ds, axis in (("memberships", 0), (READING, 1), ("sonar", 1)):
        if shape is not None and isinstance(g.get(ds), h5py.Dataset) and \
                g[ds].shape[1:] != (shape[axis],):
            fail(f"trials/{name}/{ds}", f"has shape {g[ds].shape}, which does not fit the "
                 f"fitted centres' shape {shape}")
    for label, bg in (g["behaviours"].items() if isinstance(g.get("behaviours"), h5py.Group)
                      else ()):
        policy = bg.get("policy")
        singles = bg.get("actions", bg.get("singletons"))  # (named singletons before v2)
        if not isinstance(policy, h5py.Group) or not isinstance(singles, h5py.Group):
            continue
        for out, ds in policy.items():
            if out not in singles:
                continue
            idx, n = np.asarray(ds[()]), len(singles[out])
            if idx.dtype.kind not in "iu" or (idx.size and not (0 <= idx.min() <= idx.max()
                                                                 < n)):
                fail(f"trials/{name}/behaviours/{label}/policy/{out}", f"expected action "
                     f"indices in 0..{n - 1}, got {idx.tolist()}")


def open_log(path: str | os.PathLike[str]) -> Log:
    """Open a sitframe log for reading.

    Raises
    ------
    InputError
        The file does not exist, is not HDF5, is not a sitframe log, or has a
        schema version this sitframe does not know.
    """
    p = str(path)
    if not os.path.exists(p):
        raise InputError("log file not found", file=p)
    if not h5py.is_hdf5(p):
        raise InputError("not an HDF5 file (expected a sitframe .h5 log)", file=p)
    try:
        with deferred_interrupt(), h5py.File(p, "r") as f:
            attrs = {k: _attr(v) for k, v in f.attrs.items()}
    except OSError as exc:
        raise InputError(f"cannot open HDF5 log (truncated or corrupted?): {exc}", file=p) from None
    if attrs.get("schema") != SCHEMA:
        raise InputError(f"not a sitframe log (root attribute schema is "
                         f"{attrs.get('schema')!r}, expected {SCHEMA!r})", file=p)
    version = attrs.get("schema_version")
    if not isinstance(version, int) or isinstance(version, bool) or version != SCHEMA_VERSION:
        raise InputError(f"unknown log schema version {version!r}; this sitframe reads version "
                         f"{SCHEMA_VERSION}", file=p, key="schema_version")
    return Log(p, attrs)
