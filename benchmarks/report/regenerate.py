"""Regenerate the results tables of the documentation: each table's runs and its script.

Question: none; this is the one place that knows which sweeps and which script make each
table of ``docs/results/tables/`` (so each results page gives one command).
Output: the tables (``docs/results/tables/NAME.md``, written by the scripts through
``common.publish``) and the logs they were made from (``logs/`` in the working folder).

::

    python benchmarks/report/regenerate.py --list              # every table, its cost
    python benchmarks/report/regenerate.py oa-presets ablation # make these
    python benchmarks/report/regenerate.py --cheap             # every one under ~10 minutes
    python benchmarks/report/regenerate.py --dry-run speed     # print the commands only
    python benchmarks/report/regenerate.py --pending           # mark the tables not yet made
    python benchmarks/report/regenerate.py --tables-only speed # the logs are there

A sweep whose folder already holds its complete logs is reused (``sitframe sweep
--reuse``). Runs use one worker unless ``--workers K``. The figures of a table depend on the
CPU arithmetic of the machine that made its logs (the table's last line says which; see
docs/explanation/determinism.md): the tables shipped were made with AVX2 arithmetic, on an
AVX-512 machine with ``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR"
OPENBLAS_CORETYPE=Haswell`` set.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common import ROOT  # noqa: E402
from common.publish import pending, publish, tables_dir  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # report/: pooled_table

S = "logs/sweeps"
PY = "python"


@dataclass(frozen=True)
class Recipe:
    """How a table is made: the sweeps it needs, then the commands that write it (a command
    starting with ``capture`` has its printed Markdown table published as the table)."""

    sweeps: tuple[str, ...]
    commands: tuple[str, ...]
    minutes: int  # with one worker, sweeps included, on the 2-core machine of the results
    runs: tuple[str, ...] = field(default=())  # presets to run first (sitframe run)

    @property
    def cheap(self) -> bool:
        return self.minutes <= 10


def _glob(name: str, folder: str, pattern: str) -> str:
    return shlex.quote(f"{name}::{S}/{folder}/{pattern}")


def _situations_c(c: str) -> str:
    return (f"fixed c = {c}::{S}/situations-c*/*fcm-c={c}-*.h5" if c != "auto" else
            f"c = auto::{S}/situations-c*/*c=auto*.h5")


OA = ("obstacle-avoidance", "obstacle-avoidance-q150-t5", "obstacle-avoidance-12",
      "obstacle-avoidance-16", "obstacle-avoidance-thesis")
POOLED = f"{PY} benchmarks/report/pooled_table.py"
SPEED = f"{PY} benchmarks/learning/speed_openness.py"
SITUATIONS = f"{PY} benchmarks/report/situations.py"

#: The third round of preset candidates (issue 39), published in a table of their own.
ROUND_3 = ("oa-12-cand3", "oa-12-rooms", "oa-16-cand3", "oa-8-rooms")
#: The fourth round: learning over rooms with the stricter convergence window, or longer.
ROUND_4 = ("oa-12-rooms-p150", "oa-16-rooms-p150", "oa-16-rooms-p150-i8000", "oa-8-rooms-p100",
           "oa-8-rooms-p150", "oa-8-rooms-p150-i8000", "oa-online-rooms-p100-i12000",
           "oa-online-rooms-p100-i20000-g1500-freeze",
           "oa-online-rooms-p100-i8000", "oa-online-rooms-p100-i8000-g1500",
           "oa-online-rooms-p150", "oa-online-rooms-p150-i12000-g1500",
           "oa-online-rooms-p150-i12000-g1500-freeze", "oa-online-rooms-p150-i20000-g1500",
           "oa-online-rooms-p150-i20000-g1500-freeze", "oa-online-rooms-p150-i8000",
           "oa-online-rooms-p150-i8000-g1000", "oa-online-rooms-p150-i8000-g1500",
           "oa-online-rooms-p75-i8000", "wf-12-rooms")
#: The fifth round: the wall follower over 12 situations of its own.
ROUND_5 = ("wf-12-own-space",)
#: The sixth round: -8 and -16 over rooms (Q start 250 for -16, 12,000 iterations at most for
#: -8), the on-line interpreter for up to 30,000 iterations (also frozen only after 20 updates
#: per situation), the literal thesis over rooms.
ROUND_6 = ("oa-16-rooms-p150-q250-t2", "oa-8-rooms-p150-i12000",
           "oa-online-rooms-p150-i30000-g1500-freeze",
           "oa-online-rooms-p150-i30000-g1500-freeze-mu20", "oa-thesis-rooms")
#: The seventh round: the on-line interpreter frozen only after 10, 5 or 3 updates per
#: situation (up to 30,000 iterations), and after 5 with up to 45,000.
ROUND_7 = ("oa-online-rooms-p150-i30000-g1500-freeze-mu10",
           "oa-online-rooms-p150-i30000-g1500-freeze-mu5",
           "oa-online-rooms-p150-i30000-g1500-freeze-mu3",
           "oa-online-rooms-p150-i45000-g1500-freeze-mu5")
#: ``obstacle-avoidance-12`` as it was before issue 39 moved it over rooms (one room).
OA12_ONE_ROOM = "sweeps/bases/obstacle-avoidance-12-one-room.toml"
#: ``obstacle-avoidance-8`` as it was before issue 39 moved it over rooms (one room).
OA8_ONE_ROOM = "sweeps/bases/obstacle-avoidance-8-one-room.toml"
#: ``obstacle-avoidance-online`` as it was before issue 39 moved it over rooms (one room).
ONLINE_ONE_ROOM = "sweeps/bases/obstacle-avoidance-online-one-room.toml"
#: The presets whose failing evaluations ``failing_rules.py`` takes apart, as they were when
#: they failed: the one-room ``obstacle-avoidance-12`` and ``-8`` and ``wall-following-12``
#: over -12's situations (before issue 39 changed them), whose failures the page explains.
FAILING = (OA12_ONE_ROOM, OA8_ONE_ROOM, "sweeps/bases/wall-following-12-shared.toml")


def _safety(table: str, candidates: tuple[str, ...] | list[str],
            presets: tuple[str, ...] = (), held_out: bool = False) -> str:
    """``preset_safety.py`` over candidate files (by name) and shipped presets or config
    files, 10 seeds (``held_out``: seeds 10-19, which chose nothing), published as ``table``."""
    names = [f"benchmarks/learning/preset_candidates/{c}.toml" for c in candidates]
    return (f"{PY} benchmarks/learning/preset_safety.py --seeds 10"
            f"{' --first-seed 10' if held_out else ''} --presets "
            + " ".join([*names, *presets]) + f" --publish {table}")


#: Every table of docs/results/tables/, by name.
RECIPES: dict[str, Recipe] = {
    "oa-presets": Recipe(OA, (f"{POOLED} --publish oa-presets " +
                              " ".join(f"{S}/{s}" for s in OA),), 10),
    "oa-q250-vs-q150": Recipe(OA[:2], (
        f"capture sitframe compare {S}/obstacle-avoidance {S}/obstacle-avoidance-q150-t5 "
        f"-o logs/compare-q250-q150",), 4),
    "oa12-optimism": Recipe(("oa12-optimism",), (
        f"{POOLED} --publish oa12-optimism " + " ".join(
            _glob(f"{q}, {t}{' (the one-room preset)' if (q, t) == (250, 2) else ''}",
                  "oa12-optimism",
                  f"*q_init_value={q}_temperature={t}_*.h5")
            for q, t in ((150, 5), (150, 2), (250, 5), (250, 2))),), 6),
    "fuzzy-vs-crisp": Recipe(("fuzzy-vs-crisp",), (
        f"{POOLED} --publish fuzzy-vs-crisp "
        + _glob("fuzzy-q", "fuzzy-vs-crisp", "*component=fuzzy-q_*.h5") + " "
        + _glob("crisp-q", "fuzzy-vs-crisp", "*component=crisp-q_*.h5"),), 7),
    "fuzzy-vs-crisp-compare": Recipe(("fuzzy-vs-crisp",), (
        f"capture sitframe compare {S}/fuzzy-vs-crisp -o logs/compare-fuzzy-vs-crisp",), 7),
    "sensors": Recipe(("sensors",), (
        f"{POOLED} --publish sensors " + _glob("sonar ring (8 cones)", "sensors",
                                               "*sensor=pioneer-sonar*.h5")
        + " " + _glob("laser (16 rays, 180°)", "sensors", "*sensor=laser*.h5"),), 5),
    "sensors-beams": Recipe(("sensors-beams",), (
        f"{POOLED} --publish sensors-beams " + _glob("8 beams", "sensors-beams", "*beams=8_*.h5")
        + " " + _glob("32 beams", "sensors-beams", "*beams=32_*.h5"),), 4),
    "ablation": Recipe(("ablation",), (
        f"{PY} benchmarks/common/publish.py {S}/ablation/summary-pooled.md --name ablation "
        "--command 'sitframe sweep sweeps/ablation.toml'",), 10),
    "situations": Recipe(("situations", "situations-online"), (
        f"{SITUATIONS} --publish situations --figure docs/results/figures/situations.png "
        + " ".join(_glob(n, "situations", g) for n, g in (
            ("fixed c = 8", "*fcm-c=8-*.h5"), ("fixed c = 12", "*fcm-c=12-*.h5"),
            ("fixed c = 16", "*fcm-c=16-*.h5"), ("c = auto", "*c=auto*.h5"),
            ("evolving from c = 12 (the preset)", "*evolving*.h5")))
        + " " + _glob("online (the preset)", "situations-online", "*.h5"),), 17),
    "wall-following-evolving": Recipe(("wall-following", "wall-following-evolving"), (
        f"{POOLED} --publish wall-following-evolving "
        + _glob("fixed c = 16", "wall-following", "*.h5") + " "
        + _glob("evolving (the preset)", "wall-following-evolving", "*.h5"),), 9),
    "situations-c": Recipe(("situations-c", "situations-c-heldout"), (
        f"{SITUATIONS} --publish situations-c --against 'fixed c = 10' "
        + " ".join(shlex.quote(_situations_c(c)) for c in ("8", "10", "12", "14", "16")),),
        30),
    "speed-convergence": Recipe(("speed-convergence",), (
        f"{SPEED} {S}/speed-convergence logs/obstacle-avoidance-12.h5 "
        "--publish convergence=speed-convergence",), 3),
    "speed": Recipe(("speed",), (
        f"{SPEED} {S}/speed logs/obstacle-avoidance-12.h5 --publish situations=speed-situations "
        "--publish clearance=speed-clearance",
        f"{POOLED} --publish speed-safety {S}/speed"), 4),
    "wall-following": Recipe(("wall-following",), (
        f"{POOLED} --publish wall-following {S}/wall-following",), 3),
    "goal-finding": Recipe(("goal-finding",), (
        f"{POOLED} --publish goal-finding {S}/goal-finding",), 4),
    "speed-41": Recipe((), (
        f"{PY} benchmarks/learning/bench_speed.py --against b2a2035 --repeats 9 "
        "--publish speed-41",), 8),
    "gym-speed": Recipe((), (
        f"{PY} benchmarks/sim/bench_gym.py --steps 3200 --repeats 5 --against b2a2035 "
        "--publish gym-speed",), 4),
    "first-call": Recipe((), (
        f"{PY} benchmarks/sim/bench_sim.py --first-call --repeats 6 --publish first-call",), 3),
    "goal-finding-learned": Recipe(("goal-finding-learned",), (
        f"{POOLED} --publish goal-finding-learned {S}/goal-finding-learned",), 35),
    "generalisation": Recipe((), (
        f"{PY} benchmarks/learning/generalisation.py --seeds 10 --publish",), 50),
    "preset-safety": Recipe((), (
        f"{PY} benchmarks/learning/preset_safety.py --seeds 10 --publish",), 60),
    "preset-safety-20": Recipe((), (
        f"{PY} benchmarks/learning/preset_safety.py --seeds 20 --presets obstacle-avoidance "
        "obstacle-avoidance-8 obstacle-avoidance-12 obstacle-avoidance-16 "
        "obstacle-avoidance-evolving obstacle-avoidance-online speed wall-following "
        "wall-following-12 wall-following-evolving --publish preset-safety-20",), 120),
    "preset-safety-candidates": Recipe((), (_safety("preset-safety-candidates", [
        p.stem for p in sorted((ROOT / "benchmarks/learning/preset_candidates").glob("*.toml"))
        if p.stem not in ROUND_3 + ROUND_4 + ROUND_5 + ROUND_6 + ROUND_7]),), 190),
    "preset-safety-candidates-3": Recipe((), (_safety("preset-safety-candidates-3", ROUND_3),), 20),
    "preset-safety-candidates-4": Recipe((), (_safety("preset-safety-candidates-4", ROUND_4),),
                                         120),
    "preset-safety-candidates-5": Recipe((), (_safety("preset-safety-candidates-5", ROUND_5),), 5),
    "preset-safety-held-out-5": Recipe((), (
        _safety("preset-safety-held-out-5", ROUND_5, ("speed",), held_out=True),), 10),
    "arbiter-candidates": Recipe((), (
        f"{PY} benchmarks/learning/arbiter_candidates.py --publish",), 50),
    "preset-safety-candidates-6": Recipe((), (_safety("preset-safety-candidates-6", ROUND_6),),
                                         25),
    "preset-safety-held-out-6": Recipe((), (
        _safety("preset-safety-held-out-6", ROUND_6[:4], held_out=True),), 35),
    "preset-safety-candidates-7": Recipe((), (_safety("preset-safety-candidates-7", ROUND_7),),
                                         50),
    "preset-safety-held-out-7": Recipe((), (
        _safety("preset-safety-held-out-7", ROUND_7[3:], held_out=True),), 13),
    "failing-rules": Recipe((), (
        f"{PY} benchmarks/learning/preset_safety.py --seeds 10 --presets " + " ".join(FAILING),
        f"{PY} benchmarks/learning/failing_rules.py "
        + " ".join(f"logs/preset-safety/{Path(p).stem}" for p in FAILING) + " --publish"), 25),
    "preset-safety-held-out-3": Recipe((), (
        _safety("preset-safety-held-out-3", ("oa-12-rooms",), (OA12_ONE_ROOM,),
                held_out=True),), 12),
    "preset-safety-held-out-4": Recipe((), (_safety(
        "preset-safety-held-out-4", ("oa-8-rooms-p150", "oa-8-rooms-p150-i8000",
                                     "oa-12-rooms-p150",
                                     "oa-online-rooms-p100-i20000-g1500-freeze"),
        (OA8_ONE_ROOM, ONLINE_ONE_ROOM), held_out=True),), 25),
    "preset-safety-held-out": Recipe((), (_safety(
        "preset-safety-held-out", ("oa-evolving-rooms-collision100", "wf-evolving-collision100",
                                   "wf-evolving-replay4", "wf-p150", "speed-near3-av20"),
        ("obstacle-avoidance",), held_out=True),), 33),
}
def headline() -> str:
    """The README's and the results index's short table, from the sweeps' logs (a row
    whose logs are missing says how to make them)."""
    import numpy as np
    from pooled_table import BAD, pool

    def logs(folder: str) -> dict | None:
        return pool(f"{S}/{folder}") if list(Path(S, folder).glob("*.h5")) else None

    rows = ["| experiment | result, pooled over 10 seeds (× 11 trials where a run has them) "
            "| details |", "|---|---|---|",
            f"| Obstacle avoidance learnt over 10 generated rooms (the main job) | "
            f"{_generalisation()} | [generalisation](generalisation.md) |"]
    kept = _last_rows()
    for label, folder, page in (
            ("Obstacle avoidance, 12 situations, learnt in one room (thesis ch. 5)",
             "obstacle-avoidance-12", "obstacle-avoidance"),
            ("The thesis's method as printed", "obstacle-avoidance-thesis",
             "obstacle-avoidance"),
            ("Wall following (15–35 cm)", "wall-following", "wall-following"),
            ("Goal finding, CDB", "goal-finding", "goal-finding")):
        p = logs(folder)
        if p is None and label in kept:  # the sweep's logs are not here: the last figures
            rows.append(kept[label])
            continue
        if p is None:
            result = f"not yet regenerated: `sitframe sweep sweeps/{folder}.toml`"
        elif "goal" in p["per"] and "success_rate" in p["per"]["goal"]:
            g = p["per"]["goal"]
            result = (f"goal room: success {np.mean(g['success_rate']):.2f}, collision-free in "
                      f"{np.mean(g['collision_free_rate']):.2f} of the episodes")
        else:
            conv = p["conv"]
            result = f"converged {np.isfinite(conv).sum()}/{conv.size}"
            unseen = [w for w in ("novel-1", "novel-2") if w in p["per"]]
            coll = np.concatenate([p["per"][w]["collisions_per_1000"] for w in unseen])
            result += (f"; unseen rooms: {np.median(coll):g} collisions / 1000 iterations "
                       f"(median), {np.mean(coll > BAD):.0%} of the evaluations above "
                       f"{BAD:.0f}")
            band = [p["per"][w]["wall_band_fraction"] for w in p["per"]
                    if "wall_band_fraction" in p["per"][w] and w not in unseen]
            if band:
                result += f"; wall in the band {np.median(band[0]):.0%} of the time (median)"
        rows.append(f"| {label} | {result} | [{page}]({page}.md) |")
    rows.append(f"| Learned arbitration (own situations per behaviour, route planner) | "
                f"{_paired_arbiters()} | [learned-arbitration](learned-arbitration.md) |")
    rows.append(f"| The duel: fuzzy Q vs DQN and PPO | {_duel()} | [duel](duel.md) |")
    return "\n".join(rows)


def _last_rows() -> dict[str, str]:
    """The rows of the headline table as last published, by experiment (a row whose sweep
    logs are not in this folder keeps the figures its last regeneration measured)."""
    table = tables_dir() / "headline.md"
    lines = table.read_text("utf-8").splitlines() if table.is_file() else []
    return {line.split("|")[1].strip(): line for line in lines
            if line.startswith("| ") and "not yet regenerated" not in line}


def _generalisation() -> str:
    """The main job's row, read from the table benchmarks/learning/generalisation.py
    published (its ``shipped`` recipe: the preset as it is)."""
    table = tables_dir() / "generalisation.md"
    rows = [[c.strip() for c in line.split("|")[1:-1]]
            for line in (table.read_text("utf-8").splitlines() if table.is_file() else [])
            if line.startswith("| `shipped` |")]
    if not rows:
        return "not yet regenerated: `python benchmarks/report/regenerate.py generalisation`"
    r = rows[0]
    return (f"{r[2]} seeds, one trial each, judged in 20 generated rooms it never saw: "
            f"{r[3].split(' ')[0]} collisions / 1000 iterations (median; worst seed {r[4]}), "
            f"coverage {r[5]} (worst seed {r[6]}); {r[7]} of the evaluations above 10")


def _duel() -> str:
    """The duel's row, read from the table benchmarks/duel/duel.py published (duel.md): per
    method, test-room collisions and coverage (median, worst seed), its steps and the
    collisions it had while learning."""
    table = tables_dir() / "duel.md"
    rows = [[c.strip() for c in line.split("|")[1:-1]]
            for line in (table.read_text("utf-8").splitlines() if table.is_file() else [])
            if line.startswith("| ") and not line.startswith(("| method", "| target"))]
    rows = [r for r in rows if len(r) >= 7 and r[1].isdigit()]
    if not rows:
        return "not yet regenerated: `python benchmarks/duel/duel.py report` (the page)"
    parts = [f"{r[0]}: {r[2].split(' ')[0]} collisions / 1000 (worst seed "
             f"{r[2].rsplit(' ', 1)[-1]}), coverage {r[3].split(' ')[0]}, "
             f"{r[4].split(' ')[0]} steps, {r[6].split(' ')[0]} collisions while learning"
             for r in rows]
    return f"22 rooms no method saw, {rows[0][1]} seeds each: " + "; ".join(parts)


def _paired_arbiters() -> str:
    """The learned arbitration's row, read from the tables benchmarks/learning/
    paired_arbiters.py published (rooms.md, office.md)."""
    import re

    rooms, office = tables_dir() / "rooms.md", tables_dir() / "office.md"
    pooled = re.search(r"Collision-free pooled over the rooms: learned (\d+\.\d+), CDB (\d+\.\d+)",
                       rooms.read_text("utf-8")) if rooms.is_file() else None
    rows = [line.split("|") for line in office.read_text("utf-8").splitlines()
            if line.startswith("| office | learned |")] if office.is_file() else []
    if pooled is None or not rows:
        return "not yet regenerated: `python benchmarks/learning/paired_arbiters.py` (the page)"
    verdicts: dict[str, bool] = {}  # room -> learned >= CDB on every figure (paired, Holm)
    for table in (rooms, office):
        for line in table.read_text("utf-8").splitlines():
            cells = [c.strip() for c in line.strip("|").split("|")]
            if len(cells) == 9 and cells[-1] in ("yes", "**no**"):
                verdicts[cells[0]] = verdicts.get(cells[0], True) and cells[-1] == "yes"
    worse = [r for r, ok in verdicts.items() if not ok]
    return (f"7 rooms × 10 seeds × 50 goal pairs: collision-free {pooled[1]} pooled (CDB "
            f"{pooled[2]}); office with doors: success {float(rows[0][4]):.2f}, SPL "
            f"{float(rows[0][10]):.2f}; at least CDB's equal on success, collision-free and "
            f"SPL (paired, Holm) in {len(verdicts) - len(worse)} of {len(verdicts)} rooms"
            + (f" (not: {', '.join(worse)})" if worse else ""))


def publish_headline() -> None:
    """``headline.md``, and the same table in README.md between its markers."""
    table = headline()
    publish("headline", table, command="python benchmarks/report/regenerate.py headline")
    readme = ROOT / "README.md"
    text = readme.read_text("utf-8")
    start, end = "<!-- headline:start -->\n", "<!-- headline:end -->"
    before, _, rest = text.partition(start)
    _, _, after = rest.partition(end)
    readme.write_text(before + start + readme_table(table) + "\n" + end + after, "utf-8")


def readme_table(table: str) -> str:
    """The headline table with its links from README.md (the results pages in docs/)."""
    import re

    return re.sub(r"\]\(([\w-]+\.md)\)", r"](docs/results/\1)", table)


#: Tables another script makes on its own (not from here): name -> how.
ELSEWHERE = {
    "duel-tuning": "python benchmarks/duel/duel.py report --out logs/duel2",
    "duel": "python benchmarks/duel/duel.py report --out logs/duel2",
}
#: The table each sub-table is made with (a recipe may write several tables).
WRITES = {"speed": ("speed-situations", "speed-clearance", "speed-safety")}


def commands(name: str, workers: int, tables_only: bool = False) -> list[str]:
    """The shell commands that make table ``name``, in order (``tables_only``: the logs are
    there; only the table's script)."""
    r = RECIPES[name]
    out = [] if tables_only else [f"sitframe run {p} --workers {workers}" for p in r.runs]
    if not tables_only:
        out += [f"sitframe sweep sweeps/{s}.toml --reuse --workers {workers}"
                for s in r.sweeps]
    return out + list(r.commands)


def run(name: str, workers: int, dry_run: bool, tables_only: bool = False) -> None:
    for cmd in commands(name, workers, tables_only):
        print(f"$ {cmd}", flush=True)
        if dry_run:
            continue
        capture = cmd.startswith("capture ")
        argv = shlex.split(cmd.removeprefix("capture "))
        argv = [_here(a) for a in argv]
        if argv[0] == "sitframe":
            argv = [sys.executable, "-m", "sitframe.cli", *argv[1:]]
        elif argv[0] == PY:
            argv[0] = sys.executable
        res = subprocess.run(argv, check=True, text=True,
                             stdout=subprocess.PIPE if capture else None)
        if capture:
            table = "\n".join(line for line in res.stdout.splitlines()
                              if line.startswith("|"))
            publish(name, table, command=cmd.removeprefix("capture "))


def _here(arg: str) -> str:
    """A repository path (sweeps/, benchmarks/) made absolute, so this runs from anywhere;
    logs stay relative to the working folder."""
    for top in ("sweeps/", "benchmarks/", "docs/"):
        if arg.startswith(top) and (ROOT / arg).exists():
            return str(ROOT / arg)
    return arg


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", metavar="NAME", help="tables to make")
    ap.add_argument("--list", action="store_true", help="list every table and its cost")
    ap.add_argument("--cheap", action="store_true", help="make every table of <= 10 minutes")
    ap.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    ap.add_argument("--pending", action="store_true",
                    help="mark every table not yet made with its one line")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--tables-only", action="store_true",
                    help="the logs are made: run only the tables' scripts")
    args = ap.parse_args()
    if args.list:
        for name, r in RECIPES.items():
            print(f"{name:<26} ~{r.minutes:>3} min{'' if r.cheap else '  (expensive)'}")
        for name, how in ELSEWHERE.items():
            print(f"{name:<26} made by {how}")
        return 0
    if args.pending:
        for name in ["headline", *RECIPES, *ELSEWHERE]:
            for table in WRITES.get(name, (name,)):
                if (tables_dir() / f"{table}.md").exists():
                    continue
                if name in ELSEWHERE:
                    pending(table, ELSEWHERE[name], "after the duel's runs: see the page")
                elif name == "headline":
                    pending(table, f"python {Path(__file__).relative_to(ROOT)} headline",
                            "after the sweeps of the rows")
                else:
                    r = RECIPES[name]
                    pending(table, f"python {Path(__file__).relative_to(ROOT)} {table}",
                            f"{'expensive: ' if not r.cheap else ''}about {r.minutes} min "
                            "with one worker")
        return 0
    made_by = {t: r for r, tables in WRITES.items() for t in tables}
    names = [made_by.get(n, n) for n in args.names] or \
        ([n for n, r in RECIPES.items() if r.cheap] if args.cheap else [])
    names = list(dict.fromkeys(names))
    unknown = [n for n in names if n not in RECIPES and n != "headline"]
    if unknown or not names:
        print(f"regenerate: {'unknown table ' + ', '.join(unknown) if unknown else 'no table'}"
              f"; expected some of: {', '.join(RECIPES)}", file=sys.stderr)
        return 2
    for name in names:
        if name == "headline":
            if not args.dry_run:
                publish_headline()
            continue
        run(name, args.workers, args.dry_run, args.tables_only)
    return 0


if __name__ == "__main__":
    sys.exit(main())
