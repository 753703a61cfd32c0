"""Situations: fuzzy c-means clustering of sensor readings into fuzzy situations.

What it holds
    :mod:`~sitframe.situations.fcm` (fuzzy c-means, memberships, validity measures),
    :mod:`~sitframe.situations.clustering` (the clustering stage: FCM trials, trial
    selection, sweeps over c, prototype descriptions),
    :mod:`~sitframe.situations.labels` (labels of a set of situations, no two alike),
    :mod:`~sitframe.situations.events` (situations that change during a trial: the
    events an evolving interpreter reports and the arrays that record them).

What it may import
    :mod:`sitframe.sim` (its compiled kernels) and the ground floor; never the plugin
    contract, runs, logs or analysis.

Entry points
    :func:`~sitframe.situations.fcm.fcm`, :func:`~sitframe.situations.fcm.memberships`,
    :func:`~sitframe.situations.fcm.validity`,
    :func:`~sitframe.situations.clustering.cluster_trials`,
    :class:`~sitframe.situations.events.SituationEvent`. The names of the former module
    ``sitframe.situations`` (``SituationEvent``, ``accumulate_errors``, ...) are served
    from here.
"""

from __future__ import annotations

import importlib
from typing import Any

_EVENTS = ("KINDS", "SituationEvent", "accumulate_errors", "history_arrays",
           "count_per_iteration")


def __getattr__(name: str) -> Any:
    if name in _EVENTS:
        events = importlib.import_module("sitframe.situations.events")

        return getattr(events, name)
    raise AttributeError(f"module 'sitframe.situations' has no attribute {name!r}")
