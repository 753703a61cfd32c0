"""sitframe: situation-based navigation behaviours for a simulated mobile robot.

Sonar readings are clustered by fuzzy c-means into fuzzy *situations*; a fuzzy
rule base maps situations to actions; fuzzy Q-learning learns that rule base
online from a reward. Every component is a pluggy plugin; every run is logged
to HDF5.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
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
#: (``from sitframe import hookimpl, Proposal, Transition``): name -> the module that
#: defines it. Loaded on first use, so ``import sitframe`` (and the CLI's start-up) stays
#: fast. Plugins import nothing else of sitframe (checked by import-linter).
_PUBLIC: dict[str, str] = {
    # component protocols and the run lifecycle
    **dict.fromkeys(("Sensor", "SituationInterpreter", "Reward", "Behaviour", "Arbiter",
                     "EvaluationProtocol"), "contract.components"),
    # records crossing the plugin boundary
    **dict.fromkeys(("Context", "Proposal", "Transition", "StepRecord", "RunInfo",
                     "TrialResult", "RunContext", "TrialInfo", "SensorSpec", "LearnedPolicy",
                     "PolicyOutput", "SpaceInfo"), "contract.records"),
    # config tables a plugin declares
    **dict.fromkeys(("ConfigKey", "ConfigTable", "ABSENT", "REQUIRED"), "contract.tables"),
    # errors
    **dict.fromkeys(("InputError", "PluginError", "PluginFault"), "errors"),
    # worlds, robot and geometry
    **dict.fromkeys(("World", "Goal", "load_world"), "sim.world"),
    **dict.fromkeys(("RobotParams", "Command", "StepOutcome"), "sim.robot"),
    **dict.fromkeys(("cast_rays", "cast_rays_many", "rim_ranges", "rim_ranges_many", "raycast",
                     "point_segment_distance", "min_distance"), "sim.geometry"),
    # situations and learning building blocks
    **dict.fromkeys(("fcm", "memberships", "MembershipFunction", "online_update",
                     "row_sq_norms"), "situations.fcm"),
    **dict.fromkeys(("cluster_trials", "sweep_c", "TaskMap", "describe_prototype"),
                    "situations.clustering"),
    **dict.fromkeys(("SituationEvent", "accumulate_errors"), "situations.events"),
    "SituationFCS": "learning.fcs",
    **dict.fromkeys(("FuzzyQLearner", "QLearningParams", "greedy_actions", "softmax_choice"),
                    "learning.fuzzy_q"),
    # metrics that know no behaviour (for evaluation protocols)
    **dict.fromkeys(("path_length", "heading_change_per_m", "spl"), "sim.metrics"),
    **dict.fromkeys(("shortest_path_length", "PathDistance", "shortest_route", "route_graph",
                     "RouteGraph"), "sim.paths"),
    # logs
    **dict.fromkeys(("open_log", "LogWriter"), "logs"),
}

#: Submodules plugin authors use as namespaces (``from sitframe import params as P``).
_MODULES = {"params": "params", "hookspecs": "contract.hookspecs"}

#: Modules of the flat layout before the subpackages (sitframe 0.1), still importable under
#: their old names (``import sitframe.fcm``) for notebooks and scripts written against it.
#: Each old name is the *same* module object as its new home.
MOVED: dict[str, str] = {
    **{m: f"sim.{m}" for m in ("world", "geometry", "robot", "fleet", "paths", "metrics",
                               "kernels", "kernels_numba", "numba_cache")},
    **{m: f"situations.{m}" for m in ("fcm", "clustering")},
    "fuzzy": "learning.fcs",
    **{m: f"contract.{m}" for m in ("hookspecs", "components", "records", "config",
                                    "pluginmanager", "resolve")},
    "frames": "logs.frames", "interrupts": "logs.interrupts", "logged": "logs.policies",
    **{m: f"runs.{m}" for m in ("loop", "collect", "experiment", "parallel", "prepare",
                                "sweep", "evaluation")},
    "resume": "runs.prepare", "pack": "cli.pack",
}

__all__ = ["__version__", "hookimpl", *_PUBLIC, *_MODULES]


def __getattr__(name: str) -> Any:
    import importlib

    if name in _PUBLIC:
        value = getattr(importlib.import_module(f"sitframe.{_PUBLIC[name]}"), name)
        globals()[name] = value
        return value
    if name in _MODULES:
        return importlib.import_module(f"sitframe.{_MODULES[name]}")
    if name in MOVED:
        return importlib.import_module(f"sitframe.{MOVED[name]}")
    raise AttributeError(f"module 'sitframe' has no attribute '{name}'")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``sitframe.<old name>`` (:data:`MOVED`) as the module at its new home.

    The import system stamps the old name's spec on the module it gets; the module keeps
    its own (its ``__spec__`` names its new home), so pickling and workers see one module.
    """

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> Any:
        old = fullname.partition("sitframe.")[2]
        if not fullname.startswith("sitframe.") or old not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: Any) -> Any:
        module = importlib.import_module(f"sitframe.{MOVED[spec.name.partition('.')[2]]}")
        spec.loader_state = module.__spec__
        return module

    def exec_module(self, module: Any) -> None:
        """Nothing to run (the module ran at its new home); give it back its own spec."""
        module.__spec__ = module.__spec__.loader_state


sys.meta_path.append(_MovedModules())
