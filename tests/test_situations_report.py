"""``benchmarks/report/situations.py``: the README's pooled situations table from sweep logs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "report" / "situations.py"


def _report(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SCRIPT), *args, "--rooms", "novel-1"],
                          capture_output=True, text=True, timeout=120)


def test_each_setting_pools_its_own_logs(two_runs):
    a, b = two_runs
    out = _report(f"A::{a}", f"B::{b}")
    assert out.returncode == 0, out.stderr
    rows = [r for r in out.stdout.splitlines() if r.startswith(("| A |", "| B |"))]
    assert len(rows) == 2
    assert all(" 4 [4, 4] " in r for r in rows)  # (4 fixed situations, 2 trials each)


def test_a_log_matched_by_two_settings_is_refused(two_runs):
    # ``*c=12-*`` also matches sweeps/situations.toml's evolving logs: pooling them into
    # the fixed row as well would be a silently wrong table.
    a, _ = two_runs
    folder = Path(a).parent
    out = _report(f"first::{a}", f"second::{folder}/*.h5")
    assert out.returncode == 2
    assert out.stdout == ""
    line, = out.stderr.strip().splitlines()[-1:]
    assert "second" in line and Path(a).name in line and "already pooled in 'first'" in line
    assert "Traceback" not in out.stderr
