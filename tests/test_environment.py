"""The environment variables sitframe reads (:data:`sitframe.params.ENVIRONMENT`).

What a user relies on: a variable set to a value it does not take is one ``sitframe: error:``
line naming the variable and what it takes, before the command does anything (no log
written), never a silent fallback to the default; unset or blank is the default. (The CLI
reference's list of them: ``test_doc_examples``.)
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from sitframe.errors import InputError
from sitframe.params import ENVIRONMENT, environment

#: A value each checked variable does not take.
BAD = {name: ("-1" if key.kind == "integer" else "sometimes")
       for name, key in ENVIRONMENT.items() if key.kind in ("choice", "integer")}


@pytest.mark.parametrize("name", sorted(BAD))
def test_a_bad_value_is_one_line_naming_the_variable_and_nothing_is_written(name, tmp_path):
    out = tmp_path / "run.h5"
    proc = subprocess.run([sys.executable, "-m", "sitframe", "run", "obstacle-avoidance",
                           "--trials", "1", "--iterations", "50", "--out", str(out)],
                          env=dict(os.environ, **{name: BAD[name]}), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [f"sitframe: error: {name}: expected "
                                        f"{proc.stderr.split('expected ', 1)[1].strip()}"]
    assert repr(BAD[name]).strip("'") in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()


def test_values_are_read_as_declared(monkeypatch):
    for name, key in ENVIRONMENT.items():
        monkeypatch.setenv(name, "  ")
        assert environment(name) == key.default  # (blank: the default)
    monkeypatch.setenv("SITFRAME_FUSED", " Wait ")
    assert environment("SITFRAME_FUSED") == "wait"
    monkeypatch.setenv("SITFRAME_SCRATCH_ROWS", "2e4")
    assert environment("SITFRAME_SCRATCH_ROWS") == 20_000
    for bad, said in (("abc", "got 'abc'"), ("2.5", "got 2.5"), ("inf", "got inf")):
        monkeypatch.setenv("SITFRAME_SCRATCH_ROWS", bad)
        with pytest.raises(InputError, match=f"SITFRAME_SCRATCH_ROWS: expected an integer in "
                                             rf"\[0, inf\), {said}"):
            environment("SITFRAME_SCRATCH_ROWS")

