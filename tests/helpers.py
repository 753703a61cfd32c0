"""Shared test helpers: a small, fast run config (seconds, not minutes)."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

#: The environment of a run a test kills part-way: its trials on the Python loop
#: (``SITFRAME_FUSED=0``, the same results), so that it is still running some 0.3 s after
#: its first trial is logged; compiled, the small config's eight trials take less.
KILLABLE = dict(os.environ, SITFRAME_FUSED="0")


def small_config(
    *,
    name: str = "small",
    trials: int = 2,
    iterations: int = 300,
    seed: int = 3,
    c: int = 6,
    fcm_trials: int = 4,
    sweep: tuple[int, ...] = (),
    eval_worlds: tuple[str, ...] = ("novel-1",),
    eval_iterations: int = 100,
) -> str:
    """TOML text of a tiny obstacle-avoidance run: 2 collection rooms, few FCM trials,
    short learning trials with ``p = 5`` so that they converge, one short evaluation."""
    sweep_line = f"\nsweep = {list(sweep)}" if sweep else ""
    worlds = ", ".join(f'"{w}"' for w in eval_worlds)
    return f"""
[experiment]
name = "{name}"
trials = {trials}
iterations = {iterations}
seed = {seed}

[collect]
worlds = ["collect-1", "collect-2"]

[interpreter]
component = "fcm"
c = {c}
trials = {fcm_trials}{sweep_line}

[behaviours.avoid]
component = "fuzzy-q"
reward = "obstacle-avoidance"
p = 5

[evaluate]
worlds = [{worlds}]
iterations = {eval_iterations}
"""


#: The run that the interrupt tests (kill -9, Ctrl-C, SIGTERM, with 1 and 2 workers) stop
#: part-way and resume: 8 trials, so that a signal sent once the first trial is in the log
#: lands while most of the run is still to come (fixture ``interrupted_reference``).
INTERRUPTED_TRIALS, INTERRUPTED_ITERATIONS = 8, 300
INTERRUPTED = small_config(name="resume", trials=INTERRUPTED_TRIALS,
                           iterations=INTERRUPTED_ITERATIONS, seed=5)


def run_config(folder, config: str, out_name: str, *argv: str):
    """Write ``config`` to ``folder/<stem>.toml``, ``sitframe run`` it into ``folder/out_name``
    with ``--json`` plus ``argv``, assert exit 0; return ``(config_path, log_path)``."""
    from sitframe.cli.app import main

    cfg = folder / (out_name.rsplit(".", 1)[0] + ".toml")
    cfg.write_text(config)
    out = folder / out_name
    assert main(["run", str(cfg), "--out", str(out), "--json", *argv]) == 0
    return cfg, out


def run_json(capsys, *argv: str):
    """Run the CLI, assert exit 0 (showing stderr otherwise), return its stdout as JSON."""
    import json

    from sitframe.cli.app import main

    code = main(list(argv))
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


#: A 6 m x 4 m world file with one obstacle, for tests that need a world of their own.
ROOM = """
name = "room"

[robot]
start = [1.0, 1.0, 90.0]

[[walls]]
points = [[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]

[[obstacles]]
points = [[4, 2.5], [5, 2.5], [5, 3.2], [4, 3.2]]
"""


class Disk:
    """A folder on a tmpfs of its own (``size`` in bytes, changed by :meth:`resize`)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder

    def resize(self, size: int) -> None:
        subprocess.run(["mount", "-o", f"remount,size={size}", str(self.folder)], check=True)


@contextmanager
def small_tmpfs(folder: Path, size: str) -> Iterator[Disk]:
    """A tmpfs of ``size`` (``mount``'s, e.g. ``"4m"``) mounted on the new ``folder``: a real
    full disk. Skips the test where mounting needs root or the system does not allow it
    (the injected ENOSPC tests cover the path there)."""
    folder.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root (the injected ENOSPC tests cover the path)")
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
                         capture_output=True, text=True)
    if res.returncode:
        pytest.skip(f"this system does not allow mounting a tmpfs ({res.stderr.strip()}); "
                    "the injected ENOSPC tests cover the path")
    try:
        yield Disk(folder)
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)
