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
def interrupted_reference(tmp_path_factory):
    """``(config, log)`` of the uninterrupted serial run an interrupted and resumed run must
    reproduce bit for bit (shared by test_resume and test_hostile_input)."""
    from helpers import INTERRUPTED, run_config

    return run_config(tmp_path_factory.mktemp("interrupted"), INTERRUPTED, "reference.h5",
                      "--workers", "1")
