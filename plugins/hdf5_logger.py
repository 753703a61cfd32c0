"""Observer plugin: writes the run to an HDF5 log (layout in :mod:`sitframe.logs`).

It holds no file open: every stage and every finished trial is one
crash-safe transaction (:class:`sitframe.logs.writer.LogWriter`: a trial goes to its
own file, linked from the run file; the run's end packs them into the run
file, whatever its status), so a run
killed at any moment leaves a readable log whose root ``status`` says
``running`` (never finished) or ``aborted`` (Ctrl-C), with every trial
written so far intact; ``sitframe run --resume LOG`` finishes it (the run
then has ``RunInfo.extra["resume"]`` set and the log is reopened, not
recreated).

Only the process that runs the scheduler calls these hooks: with parallel
trials the workers return their data and this plugin writes them, in trial
order, as they finish.

Nothing is written when the run has no output path (``RunInfo.out is None``).

Its ``sitframe_trial_end`` and ``sitframe_run_end`` run *last* (``trylast``):
another observer's ``sitframe_trial_end`` may still add arrays to
``trial.plugin_data["<its plugin name>"]``, and they are written in the same
transaction as the trial.

The process holds the log's lock (:func:`sitframe.logs.writer.lock_log`) from the
run's start to its end, so a second writer of the same log is refused.
"""

from __future__ import annotations

import json

from sitframe import LogWriter, RunInfo, TrialResult, hookimpl


def _writer(run: RunInfo) -> LogWriter | None:
    return LogWriter(run.out) if run.out else None


@hookimpl
def sitframe_run_start(run: RunInfo) -> None:
    w = _writer(run)
    if w is not None:
        w.start(run, resume=bool(run.extra.get("resume")))
        run.extra["log_started"] = True  # only a log this run started gets its status


@hookimpl
def sitframe_stage_end(run: RunInfo, stage: str, data: dict) -> None:
    w = _writer(run)
    if w is None:
        return
    data = dict(data)
    if stage == "cluster" and "measure_names" in data:
        data["measure_names"] = json.dumps(list(data["measure_names"]))
    w.stage(stage, data)


@hookimpl(trylast=True)
def sitframe_trial_end(run: RunInfo, trial: TrialResult) -> None:
    w = _writer(run)
    if w is not None:
        w.trial(trial, list(run.config.get("behaviours", {})))


@hookimpl(trylast=True)
def sitframe_run_end(run: RunInfo, status: str) -> None:
    w = _writer(run)
    if w is None:
        return
    try:
        if run.extra.get("log_started") and w.path.exists():
            w.set_status(status, failure=run.extra.get("failure"))
    finally:
        w.release()  # the run is over: another process may write this log now
