"""sitframe: situation-based navigation behaviours for a simulated mobile robot.

Sonar readings are clustered by fuzzy c-means into fuzzy *situations*; a fuzzy
rule base maps situations to actions; fuzzy Q-learning learns that rule base
online from a reward. Every component is a pluggy plugin; every run is logged
to HDF5.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pluggy

__version__ = "0.1.0"

# Installed, ``plugins/`` and ``worlds/`` become ``sitframe.plugins`` and
# ``sitframe.worlds`` (setuptools package-dir). When this package is imported
# straight from a source checkout instead -- a notebook or ``python -c`` started
# in the repository root, or a multiprocessing forkserver whose ``sys.path``
# starts with the current directory -- map them the same way.
_checkout = Path(__file__).resolve().parent.parent
if (_checkout / "pyproject.toml").is_file() and (_checkout / "plugins" / "__init__.py").is_file():
    __path__.append(str(_checkout))  # noqa: F821 - a package's __path__ is always defined

#: Decorator plugin authors use to implement a hook (``@sitframe.hookimpl``).
hookimpl = pluggy.HookimplMarker("sitframe")

#: Everything a plugin author needs, importable from ``sitframe`` itself
#: (``from sitframe import hookimpl, Proposal, Transition``). Loaded on first
#: use, so ``import sitframe`` (and the CLI's start-up) stays fast.
_PUBLIC: dict[str, str] = {
    # component protocols and the run lifecycle
    "Sensor": "components", "SituationInterpreter": "components", "Reward": "components",
    "Behaviour": "components", "Arbiter": "components", "EvaluationProtocol": "components",
    # records crossing the plugin boundary
    "Context": "records", "Proposal": "records", "Transition": "records",
    "StepRecord": "records", "RunInfo": "records", "TrialResult": "records",
    "RunContext": "records", "TrialInfo": "records", "SensorSpec": "records",
    "LearnedPolicy": "records", "PolicyOutput": "records",
    # errors
    "InputError": "errors", "PluginError": "errors", "PluginFault": "errors",
    # worlds, robot and geometry
    "World": "world", "Goal": "world", "load_world": "world",
    "RobotParams": "robot", "Command": "robot", "StepOutcome": "robot",
    "cast_rays": "geometry", "cast_rays_many": "geometry", "rim_ranges": "geometry",
    "rim_ranges_many": "geometry",
    "raycast": "geometry",
    "point_segment_distance": "geometry", "min_distance": "geometry",
    # situations and learning building blocks
    "fcm": "fcm", "memberships": "fcm", "MembershipFunction": "fcm",
    "online_update": "fcm", "row_sq_norms": "fcm",
    "cluster_trials": "clustering", "sweep_c": "clustering", "TaskMap": "clustering",
    "describe_prototype": "clustering",
    "SituationFCS": "fuzzy", "FuzzyQLearner": "learning", "QLearningParams": "learning",
    "greedy_actions": "learning", "softmax_choice": "learning",
    "SituationEvent": "situations", "accumulate_errors": "situations",
    # metrics that know no behaviour (for evaluation protocols)
    "path_length": "metrics", "heading_change_per_m": "metrics", "spl": "metrics",
    "shortest_path_length": "paths", "PathDistance": "paths",
    # logs
    "open_log": "logs", "LogWriter": "logs",
}

#: Submodules plugin authors use as namespaces (``from sitframe import params as P``).
_MODULES = ("params", "hookspecs")

__all__ = ["__version__", "hookimpl", *_PUBLIC, *_MODULES]


def __getattr__(name: str) -> Any:
    import importlib

    if name in _PUBLIC:
        value = getattr(importlib.import_module(f"sitframe.{_PUBLIC[name]}"), name)
        globals()[name] = value
        return value
    if name in _MODULES:
        return importlib.import_module(f"sitframe.{name}")
    raise AttributeError(f"module 'sitframe' has no attribute '{name}'")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
