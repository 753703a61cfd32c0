"""Every shipped preset, run on a short setting, hashed: the proof a refactor changed no bit.

A refactor (a new layout, a compiled loop) must leave every preset's log bit-identical. Full
runs take minutes; this runs each preset with its own components and settings but few trials,
iterations, samples and episodes (:func:`shorten`), in dependency order (a preset's
``[prerequisites]`` point at the short runs of the presets they name), and hashes each log's
contents (:func:`sitframe.logs.compare.log_contents`: every dataset and attribute below the
root). ``tests/data/preset_digests.json`` holds the digests per arithmetic (numpy, its SIMD
targets and its BLAS kernel decide the last bits; see :mod:`sitframe.runs.arithmetic`).

Record the digests of this machine's arithmetic (after a change that is *meant* to change
logs, and say so in the commit)::

    python tests/preset_digests.py --record
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.cli import main as cli_main
from sitframe.contract.config import list_presets, load_config, to_toml
from sitframe.logs.compare import log_contents
from sitframe.runs.arithmetic import arithmetic

DIGESTS = Path(__file__).parent / "data" / "preset_digests.json"


def shorten(cfg: dict[str, Any], made: dict[str, str]) -> dict[str, Any]:
    """``cfg`` on a short setting: 1 trial of <= 300 iterations, small collect and clustering,
    100-iteration evaluations, 2 goal episodes; prerequisites point at the short configs
    already written (``made``: preset name -> file name)."""
    e = cfg["experiment"]
    e["trials"], e["iterations"] = 1, min(int(e["iterations"]), 300)
    if "collect" in cfg and "wander_samples" in cfg["collect"]:
        cfg["collect"]["wander_samples"] = min(int(cfg["collect"]["wander_samples"]), 40)
    if "trials" in cfg.get("interpreter", {}):
        cfg["interpreter"]["trials"] = 3
    if "evaluate" in cfg:
        cfg["evaluate"]["iterations"] = 100
    if "goal" in cfg:
        cfg["goal"]["episodes"] = 2
    for b in cfg.get("behaviours", {}).values():
        trial = (b.get("policy_from") or {}).get("trial")
        if isinstance(trial, dict):
            trial["episodes"] = 2
    if "prerequisites" in cfg:
        cfg["prerequisites"] = {log: made[name] for log, name in cfg["prerequisites"].items()}
    return cfg


def digest(path: Path) -> str:
    """SHA-256 over a log's contents below the root, in path order."""
    h = hashlib.sha256()
    for key, value in sorted(log_contents(path).items()):
        h.update(key.encode())
        if value is not None:
            a = np.asarray(value)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(repr(a.tolist()).encode() if a.dtype.kind == "O" else a.tobytes())
    return h.hexdigest()


def run_all(folder: Path) -> dict[str, str]:
    """Run every preset short in ``folder`` (prerequisites first); preset -> digest."""
    made: dict[str, str] = {}
    todo = list_presets()
    while todo:
        for name in list(todo):
            cfg, _source, _base = load_config(name)
            needs = set(cfg.get("prerequisites", {}).values())
            if needs - set(made):
                continue
            file = folder / f"{name}.toml"
            file.write_text(to_toml(shorten(cfg, made)), encoding="utf-8")
            made[name] = file.name
            status = cli_main(["run", str(file), "--out", str(folder / "logs" / f"{name}.h5"),
                               "--workers", "1"])
            assert status == 0, f"{name}: sitframe run exited {status}"
            todo.remove(name)
    return {name: digest(folder / "logs" / f"{name}.h5") for name in sorted(made)}


def recorded() -> dict[str, dict[str, str]]:
    return json.loads(DIGESTS.read_text()) if DIGESTS.exists() else {}


def main() -> None:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--record", action="store_true",
                        help="write this arithmetic's digests to tests/data/preset_digests.json")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        got = run_all(Path(tmp))
    arith = arithmetic()
    if args.record:
        data = recorded() | {arith: got}
        DIGESTS.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
        print(f"recorded {len(got)} presets for {arith}")
    else:
        want = recorded().get(arith, {})
        for name, d in got.items():
            print(f"{name:28s} {d[:16]}  {'same' if want.get(name) == d else 'DIFFERS'}")
        sys.exit(0 if want == got else 1)


if __name__ == "__main__":
    main()
