"""Shared fixtures. Tests that need an empty plugin manager pass ``autoload=False``.

Property-based tests (hypothesis) explore new random examples on every local
run, which is how they keep finding edge cases (run with
``--hypothesis-seed=N`` to try other seeds). Under CI (``CI`` set, as
``.ci/run`` is run) they are derandomized: the examples are fixed by each
test's source, so a green CI cannot turn red without a code change. A case a
local run finds is pinned with ``@example`` once fixed.
"""

from __future__ import annotations

import os

import matplotlib
import pytest
from hypothesis import settings

matplotlib.use("Agg")

settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture(scope="session")
def two_runs(tmp_path_factory):
    """Two tiny runs of one config (2 trials x 300 iterations, 4 situations, evaluation in
    novel-1), seeds 5 and 6: for the report, compare and export tests."""
    from helpers import run_config, small_config

    folder = tmp_path_factory.mktemp("two-runs")
    cfg = small_config(name="tiny", seed=5, trials=2, iterations=300, c=4, fcm_trials=2)
    a = run_config(folder, cfg, "a.h5")[1]
    b = run_config(folder, cfg, "b.h5", "--seed", "6")[1]
    return a, b
