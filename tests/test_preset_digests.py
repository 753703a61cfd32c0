"""Every shipped preset's log is bit-identical to the one recorded (tests/preset_digests.py).

A refactor proves itself here: each preset runs on a short setting (its own components, few
trials and iterations) and its log's contents are hashed. The recorded digests are per
arithmetic (numpy's SIMD targets and BLAS kernel decide the last bits); a machine whose
arithmetic has none recorded is skipped, naming it and the ones recorded.

The same short logs show that every preset's situations get labels no two alike
(:func:`sitframe.analysis.results.situation_labels`, derived when a log is analysed).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from preset_digests import recorded, run_all

from sitframe.analysis.results import situation_labels
from sitframe.logs.reader import open_log
from sitframe.runs.arithmetic import arithmetic
from sitframe.situations.labels import describe_prototypes


@pytest.fixture(scope="module")
def short_presets(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    """Every preset run short once: (folder, preset -> digest of its log)."""
    folder = tmp_path_factory.mktemp("presets")
    return folder, run_all(folder)


def test_every_preset_writes_the_recorded_log(short_presets):
    want = recorded().get(arithmetic())
    if want is None:
        pytest.skip(f"no preset digests recorded for this arithmetic ({arithmetic()}); "
                    f"recorded: {sorted(recorded())}")
    got = short_presets[1]
    assert sorted(got) == sorted(want), "the shipped presets changed: record them anew"
    changed = sorted(name for name in got if got[name] != want[name])
    assert not changed, (f"these presets' logs changed: {changed} (if meant, record them: "
                         "python tests/preset_digests.py --record, and say so in the commit)")


def test_every_preset_labels_its_situations_apart(short_presets):
    """No two situations of a preset read alike: not the fitted ones (the report's figures
    and tables), not an evolving trial's final ones (its final-prototypes figure)."""
    folder, got = short_presets
    labelled = 0
    for name in got:
        lg = open_log(folder / "logs" / f"{name}.h5")
        sets = [situation_labels(lg, numbered=False)] if lg.has("cluster/state/centers") \
            else []
        for k in lg.trial_indices():
            state = lg.trial(k).situations_part("state")
            if "centers" in state:
                sets.append(describe_prototypes(np.asarray(state["centers"]),
                                                lg.sensor.angles_deg))
        for labels in sets:
            twice = {w: n for w, n in Counter(labels).items() if n > 1}
            assert not twice, f"{name}: labels given to more than one situation: {twice}"
            labelled += len(labels)
    assert labelled >= 12 * 8  # every preset's situations were labelled (12 presets, c >= 8)
