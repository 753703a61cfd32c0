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
import re
import warnings
from pathlib import Path

import matplotlib
import pytest
from _pytest.capture import CaptureFixture
from hypothesis import settings

matplotlib.use("Agg")

settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


#: The bad-input and fault corpus: every stderr its tests read (``capsys``) is scanned, and
#: every Python warning raised while they run is counted, by :func:`pytest_runtest_call`.
CORPUS = ("test_bad_input.py", "test_hostile_input.py", "test_plugin_faults.py",
          "test_faults.py")

_RAW = re.compile(r"Traceback \(most recent call last\)|^\S*\.py:\d+: \w*Warning: "
                  r"|sitframe: warning: \w*Warning in \S+:\d+: |^Exception ignored in",
                  re.MULTILINE)


#: Warnings Python's default filters never show (a user never sees them on stderr).
_HIDDEN = (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)


def stderr_problems(text: str) -> list[str]:
    """What must never reach stderr from sitframe: a traceback, a raw Python warning
    (``file.py:N: XWarning: ...``), Python's "Exception ignored in" report, or a Python
    warning the command line could only pass on as it is (``sitframe: warning: XWarning in
    file.py:N: ...``: an accepted input's edge case that sitframe neither checks nor
    explains)."""
    return [m.group(0) for m in _RAW.finditer(text)]


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item):
    """The stderr scan of the corpus: a test of :data:`CORPUS` fails if the stderr it read
    holds one of :func:`stderr_problems`, or if a Python warning was raised while it ran
    (from the command line it would have reached the terminal)."""
    if Path(str(item.fspath)).name not in CORPUS:
        return (yield)
    read: list[str] = []
    original = CaptureFixture.readouterr

    def readouterr(self):  # (every capsys.readouterr() of the test, teed)
        res = original(self)
        read.append(res.err)
        return res

    CaptureFixture.readouterr = readouterr
    try:
        with warnings.catch_warnings(record=True) as raised:
            warnings.simplefilter("always")
            result = yield
    finally:
        CaptureFixture.readouterr = original
    problems = stderr_problems("".join(read)) + [
        f"{w.category.__name__}: {w.message} ({Path(w.filename).name}:{w.lineno})"
        for w in raised if not issubclass(w.category, _HIDDEN)]
    assert not problems, f"stderr scan: {problems}"
    return result


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


@pytest.fixture(scope="session")
def interrupted_reference(tmp_path_factory):
    """``(config, log)`` of the uninterrupted serial run an interrupted and resumed run must
    reproduce bit for bit (shared by test_resume and test_hostile_input)."""
    from helpers import INTERRUPTED, run_config

    return run_config(tmp_path_factory.mktemp("interrupted"), INTERRUPTED, "reference.h5",
                      "--workers", "1")
