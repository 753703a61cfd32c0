"""Observer plugin: a progress bar over trials and iterations (rich).

Shown only when the run asks for it (``RunInfo.extra["progress"]``; the CLI
sets it when stderr is a terminal and ``--json`` is not given). Iteration
updates are throttled to every 100 iterations to keep the loop fast.

When trials run in worker processes (``--workers K > 1``, ``--scheduler``),
``sitframe_step`` fires in the workers, where this plugin has no bar
(``RunInfo.extra["step_hooks"]`` is false in the main process): only the
trials bar is shown, and it advances as each trial is logged.
"""

from __future__ import annotations

from typing import Any

from sitframe import RunInfo, StepRecord, TrialResult, hookimpl

_state: dict[str, Any] = {}


@hookimpl
def sitframe_run_start(run: RunInfo) -> None:
    if not run.extra.get("progress"):
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    progress = Progress("[progress.description]{task.description}", BarColumn(),
                        MofNCompleteColumn(), TimeRemainingColumn(), transient=False)
    progress.start()
    total = run.n_trials * run.iterations
    _state["progress"] = progress
    if run.extra.get("step_hooks", True):
        _state["task"] = progress.add_task(f"{run.name}: iterations", total=total)
    _state["trials"] = progress.add_task(f"{run.name}: trials", total=run.n_trials)


@hookimpl
def sitframe_step(record: StepRecord) -> None:
    progress = _state.get("progress")
    if progress is not None and "task" in _state and \
            record.transition.before.iteration % 100 == 99:
        progress.advance(_state["task"], 100)


@hookimpl
def sitframe_trial_end(run: RunInfo, trial: TrialResult) -> None:
    progress = _state.get("progress")
    if progress is not None:
        progress.advance(_state["trials"], 1)


@hookimpl
def sitframe_run_end(run: RunInfo, status: str) -> None:
    progress = _state.pop("progress", None)
    if progress is not None:
        progress.stop()
    _state.clear()
