"""The progress plugin: one display for a run, or one pair of bars for all points of a sweep."""

from __future__ import annotations

import pytest

from sitframe.contract.records import RunInfo
from sitframe.plugins import progress


def _info(name: str, group: str | None, n_trials: int = 3, step_hooks: bool = False) -> RunInfo:
    extra = {"progress": True, "step_hooks": step_hooks}
    if group:
        extra["progress_group"] = group
    return RunInfo(name=name, config={}, config_text="", config_hash="", seed=0, out=None,
                   n_trials=n_trials, iterations=10, plugins=[], worlds={}, extra=extra)


@pytest.fixture(autouse=True)
def _quiet(monkeypatch):
    from rich.progress import Progress

    monkeypatch.setattr(Progress, "start", lambda self: None)
    monkeypatch.setattr(Progress, "stop", lambda self: None)
    yield
    progress._state.update(progress=None, bars={}, runs={})


def test_sweep_points_share_one_trials_bar_whose_total_grows():
    runs = [_info(f"s/p{i}", "sweep s", n_trials=3) for i in range(3)]
    for r in runs:
        progress.sitframe_run_start(run=r)
    display = progress._state["progress"]
    (bar,) = [t for t in display.tasks]
    assert bar.description == "sweep s: trials" and bar.total == 9
    for r in runs:
        for _ in range(3):
            progress.sitframe_trial_end(run=r, trial=None)
    assert display.tasks[0].completed == 9
    for r in runs[:2]:
        progress.sitframe_run_end(run=r, status="complete")
    assert progress._state["progress"] is display  # still shown while a point runs
    progress.sitframe_run_end(run=runs[2], status="complete")
    assert progress._state["progress"] is None and progress._state["bars"] == {}


def test_a_run_without_progress_is_not_shown_and_in_process_runs_count_iterations():
    quiet = _info("q", None)
    quiet.extra["progress"] = False
    progress.sitframe_run_start(run=quiet)
    assert progress._state["progress"] is None
    run = _info("r", None, n_trials=2, step_hooks=True)
    progress.sitframe_run_start(run=run)
    totals = {t.description: t.total for t in progress._state["progress"].tasks}
    assert totals == {"r: trials": 2, "r: iterations": 20}
    progress.sitframe_trial_end(run=quiet, trial=None)  # another run's trial: not counted
    assert all(t.completed == 0 for t in progress._state["progress"].tasks)
    progress.sitframe_run_end(run=run, status="aborted")
    assert progress._state["progress"] is None
