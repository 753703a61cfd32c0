"""Every shipped preset's log is bit-identical to the one recorded (tests/preset_digests.py).

A refactor proves itself here: each preset runs on a short setting (its own components, few
trials and iterations) and its log's contents are hashed. The recorded digests are per
arithmetic (numpy's SIMD targets and BLAS kernel decide the last bits); a machine whose
arithmetic has none recorded is skipped, naming it and the ones recorded.
"""

from __future__ import annotations

import pytest
from preset_digests import recorded, run_all

from sitframe.runs.arithmetic import arithmetic


def test_every_preset_writes_the_recorded_log(tmp_path, capsys):
    want = recorded().get(arithmetic())
    if want is None:
        pytest.skip(f"no preset digests recorded for this arithmetic ({arithmetic()}); "
                    f"recorded: {sorted(recorded())}")
    got = run_all(tmp_path)
    capsys.readouterr()
    assert sorted(got) == sorted(want), "the shipped presets changed: record them anew"
    changed = sorted(name for name in got if got[name] != want[name])
    assert not changed, (f"these presets' logs changed: {changed} (if meant, record them: "
                         "python tests/preset_digests.py --record, and say so in the commit)")
