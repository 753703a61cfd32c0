"""Observer plugin: writes the run to an HDF5 log (layout in :mod:`sitframe.logs`).

It holds no file open: every stage and every finished trial is one
open-append-flush-close transaction, so a killed run leaves a readable log
whose root ``status`` says ``running`` (never finished) or ``aborted``.

Nothing is written when the run has no output path (``RunInfo.out is None``).
"""

from __future__ import annotations

import json

from sitframe import hookimpl
from sitframe.logs import LogWriter
from sitframe.records import RunInfo, TrialResult


def _writer(run: RunInfo) -> LogWriter | None:
    return LogWriter(run.out) if run.out else None


@hookimpl
def sitframe_run_start(run: RunInfo) -> None:
    w = _writer(run)
    if w is not None:
        w.start(run, resume=bool(run.extra.get("resume")))


@hookimpl
def sitframe_stage_end(run: RunInfo, stage: str, data: dict) -> None:
    w = _writer(run)
    if w is None:
        return
    data = dict(data)
    if stage == "cluster" and "measure_names" in data:
        data["measure_names"] = json.dumps(list(data["measure_names"]))
    w.stage(stage, data)


@hookimpl
def sitframe_trial_end(run: RunInfo, trial: TrialResult) -> None:
    w = _writer(run)
    if w is not None:
        w.trial(trial, list(run.config.get("behaviours", {})))


@hookimpl
def sitframe_run_end(run: RunInfo, status: str) -> None:
    w = _writer(run)
    if w is not None and w.path.exists():
        w.set_status(status)
