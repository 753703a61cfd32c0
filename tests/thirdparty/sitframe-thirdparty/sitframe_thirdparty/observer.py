"""Near misses and the clearance at every iteration, logged with the trial (observer)."""

from typing import Any

import numpy as np

from sitframe import StepRecord, TrialResult, hookimpl

NEAR = 0.25  # metres from the rim
_clear: dict[tuple[int, str], list[float]] = {}


@hookimpl
def sitframe_step(record: StepRecord) -> None:
    key = (record.trial, record.transition.before.world.name)
    _clear.setdefault(key, []).append(record.transition.after.nearest)


@hookimpl
def sitframe_trial_data(trial: TrialResult) -> dict[str, Any] | None:
    clear = _clear.pop((trial.index, trial.world), None)
    if clear is None:
        return None
    c = np.asarray(clear, dtype=float)
    return {"near_misses": int((c < NEAR).sum()), "closest_m": float(c.min()), "clearance": c}
