"""Observer plugin: a progress bar over trials and iterations (rich).

Shown only when the run asks for it (``RunInfo.extra["progress"]``; the CLI
sets it when stderr is a terminal and ``--json`` is not given). Iterations
are counted from ``sitframe_progress`` (every 100 iterations), which keeps trials on their
compiled path.

Runs that share a ``RunInfo.extra["progress_group"]`` (the points of a sweep)
share one pair of bars, whose totals grow as each run starts; several runs
in one process show on one rich display, closed when the last run ends.

When trials run in worker processes (``--workers K > 1``, ``--scheduler``),
``sitframe_progress`` fires in the workers, where this plugin has no bar
(``RunInfo.extra["step_hooks"]`` is false in the main process): only the
trials bar is shown, and it advances as each trial is logged.
"""

from __future__ import annotations

from typing import Any

from sitframe import RunInfo, TrialResult, hookimpl

#: The shared display, its bars per group (``{"trials": id, "iterations": id}``) and
#: the group of each run still running (by run name).
_state: dict[str, Any] = {"progress": None, "bars": {}, "runs": {}}


def _group(run: RunInfo) -> str:
    return str(run.extra.get("progress_group") or run.name)


@hookimpl
def sitframe_run_start(run: RunInfo) -> None:
    if not run.extra.get("progress"):
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    if _state["progress"] is None:
        _state["progress"] = Progress("[progress.description]{task.description}", BarColumn(),
                                      MofNCompleteColumn(), TimeRemainingColumn(),
                                      transient=False)
        _state["progress"].start()
    progress, group = _state["progress"], _group(run)
    bars = _state["bars"].setdefault(group, {})
    _state["runs"][run.name] = group
    want = {"trials": run.n_trials}
    if run.extra.get("step_hooks", True):
        want["iterations"] = run.n_trials * run.iterations
    for kind, n in want.items():
        if kind in bars:
            progress.update(bars[kind], total=progress.tasks[bars[kind]].total + n)
        else:
            bars[kind] = progress.add_task(f"{group}: {kind}", total=n)


def _bar(kind: str) -> tuple[Any, Any] | tuple[None, None]:
    """The display and the bar of ``kind`` for the only running group (steps carry no run)."""
    progress = _state["progress"]
    if progress is None or len(_state["bars"]) != 1:
        return None, None
    bars = next(iter(_state["bars"].values()))
    return (progress, bars[kind]) if kind in bars else (None, None)


@hookimpl
def sitframe_progress(trial: int, iterations: int) -> None:
    progress, bar = _bar("iterations")
    if progress is not None:
        progress.advance(bar, iterations)


@hookimpl
def sitframe_trial_end(run: RunInfo, trial: TrialResult) -> None:
    group = _state["runs"].get(run.name)
    if group is not None:
        _state["progress"].advance(_state["bars"][group]["trials"], 1)


@hookimpl
def sitframe_run_end(run: RunInfo, status: str) -> None:
    if _state["runs"].pop(run.name, None) is None:
        return
    if not _state["runs"]:
        _state["progress"].stop()
        _state.update(progress=None, bars={})
