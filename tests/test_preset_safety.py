"""The main preset stays safe in rooms it never saw (issue 39), at a reduced scale.

``benchmarks/learning/preset_safety.py`` measures every preset over 10 seeds x its trials;
this runs the main job's first three trials (seed 0) and judges each frozen rule base in
three development rooms, as ``sitframe evaluate LOG --world W --trial K`` does. A change
that made the shipped rule bases collide more than 10 times per 1000 iterations there fails
it (they collide at most twice, measured when the preset learnt over rooms with evolving
situations).
"""

from __future__ import annotations

import contextlib
import io

from sitframe.cli.app import main
from sitframe.runs.evaluation import evaluate_log

ROOMS = ("gen:2000000", "gen:2000001", "gen:2000002")


def test_the_main_presets_frozen_rule_bases_are_safe_in_unseen_rooms(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "oa.h5"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["run", "obstacle-avoidance", "--trials", "3", "--seed", "0",
                     "--workers", "1", "--out", str(out)]) == 0
    rates = {(k, w): evaluate_log(str(out), world=w, trial=k)["collisions_per_1000"]
             for k in range(3) for w in ROOMS}
    assert max(rates.values()) <= 10.0, rates
