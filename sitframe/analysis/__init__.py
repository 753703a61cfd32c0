"""Offline analysis of sitframe HDF5 logs: arrays, tables and matplotlib figures.

What it holds
    Numbers and tables (:mod:`~sitframe.analysis.results`), figures
    (:mod:`~sitframe.analysis.clustering_plots`, :mod:`~sitframe.analysis.learning_plots`,
    :mod:`~sitframe.analysis.situation_plots`), the HTML report with its replay
    (:mod:`~sitframe.analysis.report`, :mod:`~sitframe.analysis.report_html`,
    :mod:`~sitframe.analysis.replay_data`), animations (:mod:`~sitframe.analysis.replay`),
    comparisons of runs and sweeps with rank tests (:mod:`~sitframe.analysis.compare`,
    :mod:`~sitframe.analysis.compare_report`), tidy exports
    (:mod:`~sitframe.analysis.export`) and what plugins logged, for the report
    (:mod:`~sitframe.analysis.plugin_data`).

What it may import
    :mod:`sitframe.logs` (it reads what runs wrote), :mod:`sitframe.contract` (records),
    :mod:`sitframe.situations`, :mod:`sitframe.sim` (worlds, drawing) and the ground floor;
    never :mod:`sitframe.runs` (analysis does not run anything) or the command line.

Entry points
    The names below, loaded lazily (importing :mod:`sitframe.analysis` does not import
    matplotlib): :func:`analyse` (the whole report), :func:`as_log`, the tables and figures.

Example
-------
>>> from sitframe import analysis as A
>>> log = A.as_log("logs/obstacle-avoidance.h5")            # doctest: +SKIP
>>> print(A.rule_base_table(log, 0).to_markdown())            # doctest: +SKIP
>>> A.plot_exploration(A.exploration_counts(log.trial(0))).savefig("x.png")  # doctest: +SKIP
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS: dict[str, str] = {
    # results: arrays, dataclasses, tables
    **{name: "sitframe.analysis.results" for name in (
        "CollisionIntervals", "Table", "as_log", "clustering_trials", "collision_intervals",
        "convergence_iteration", "convergence_table", "evaluation_episodes",
        "exploration_counts", "learned_output", "lookup_table", "representative_trial",
        "reward_per_window", "robot_radius", "rule_base_table", "rule_bases_across_trials",
        "sensor_angles", "sensor_max_range", "situation_labels", "sweep_result")},
    # figures
    **{name: "sitframe.analysis.clustering_plots" for name in (
        "OKABE_ITO", "plot_measures_by_c", "plot_measures_by_trial", "plot_prototypes")},
    **{name: "sitframe.analysis.learning_plots" for name in (
        "plot_collision_intervals", "plot_evaluation_paths",
        "plot_exploration", "plot_learning_curves", "plot_reward_per_window",
        "plot_trajectory")},
    "plot_world": "sitframe.sim.draw",
    # whole report, animation
    "AnalysisReport": "sitframe.analysis.report",
    "analyse": "sitframe.analysis.report",
    "log_problems": "sitframe.analysis.report",
    "replay": "sitframe.analysis.replay",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'sitframe.analysis' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
