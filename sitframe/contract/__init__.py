"""The plugin contract: what a run is made of, and what a plugin may rely on.

What it holds
    :mod:`~sitframe.contract.hookspecs` (every hook a plugin may implement),
    :mod:`~sitframe.contract.components` (the component protocols: Sensor,
    SituationInterpreter, Reward, Behaviour, Arbiter, EvaluationProtocol),
    :mod:`~sitframe.contract.records` (the immutable records that cross the plugin
    boundary), :mod:`~sitframe.contract.config` (the typed run config: TOML files and
    presets validated), :mod:`~sitframe.contract.tables` (the config tables plugins declare:
    checked, filled in, logged and listed like the core's),
    :mod:`~sitframe.contract.pluginmanager` (discovery by entry points
    and plugin folders, the component registry), :mod:`~sitframe.contract.resolve` (a
    config resolved against the registry into fresh, bound components), and
    :mod:`~sitframe.contract.checks` (the contract enforced: protocol checks at creation,
    value checks at the boundary, plugin faults named).

What it may import
    :mod:`sitframe.sim` and the ground floor; :mod:`sitframe.situations` and
    :mod:`sitframe.learning` are not needed by it and not imported. Plugins never import
    this package: they import the public face, ``from sitframe import ...``.

Entry points
    :func:`~sitframe.contract.config.load_config`,
    :func:`~sitframe.contract.pluginmanager.get_plugin_manager`,
    :class:`~sitframe.contract.pluginmanager.Registry`,
    :class:`~sitframe.contract.resolve.Resolved`. The names of the former module
    ``sitframe.contract`` (``fault``, ``check_protocol``, ...) are served from here.
"""

from __future__ import annotations

import importlib
from typing import Any


def __getattr__(name: str) -> Any:
    checks = importlib.import_module("sitframe.contract.checks")

    if not name.startswith("_") and hasattr(checks, name):
        return getattr(checks, name)
    raise AttributeError(f"module 'sitframe.contract' has no attribute {name!r}")
