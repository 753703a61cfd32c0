"""Write a results table where the documentation includes it: ``docs/results/tables/NAME.md``.

Question: none; this is how the scripts that measure put their tables in the docs (the
results pages include ``NAME.md`` with pymdownx.snippets), so no table is ever copied by
hand.
Output: ``NAME.md``: the table, then one line saying which command made it, with which
sitframe and commit, when. ``SITFRAME_TABLES_DIR`` writes elsewhere (the tests do).

From a script::

    from common.publish import publish
    publish("oa-presets", markdown_table)          # the command is this process's argv

From the shell, for a table a command already wrote (a sweep's ``summary-pooled.md``, a
comparison's ``compare.md``)::

    python benchmarks/common/publish.py logs/sweeps/ablation/summary-pooled.md \\
        --name ablation --command "sitframe sweep sweeps/ablation.toml"

``--pending NAME --command CMD`` writes the one line a page shows until the table is made.
"""

from __future__ import annotations

import argparse
import datetime
import os
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def tables_dir() -> Path:
    """Where the tables go: ``SITFRAME_TABLES_DIR``, else the docs' results tables."""
    return Path(os.environ.get("SITFRAME_TABLES_DIR") or ROOT / "docs" / "results" / "tables")


def _commit() -> str:
    try:
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--",
                                "sitframe", "plugins"], capture_output=True, text=True,
                               check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown commit"
    return f"commit {head}" + (" with uncommitted changes" if dirty else "")


def this_command() -> str:
    """The command line of this process, as a user would type it from the repository."""
    def from_root(arg: str) -> str:  # (a path in the repository, as typed from its root)
        try:
            return Path(arg).resolve().relative_to(ROOT).as_posix()
        except ValueError:
            return arg

    args = [a if not Path(a).is_absolute() else from_root(a) for a in sys.argv[1:]]
    return shlex.join(["python", from_root(sys.argv[0]), *args])


def publish(name: str, table: str, *, command: str | None = None) -> Path:
    """Write ``table`` (Markdown) as ``NAME.md``, with the line that says how it was made."""
    from sitframe import __version__
    from sitframe.runs.arithmetic import arithmetic_versions

    arith = arithmetic_versions()
    path = tables_dir() / f"{name}.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    when = datetime.date.today().isoformat()
    path.write_text(f"{table.strip()}\n\n*Made by `{command or this_command()}` (sitframe "
                    f"{__version__}, {_commit()}; numpy {arith['numpy']} with SIMD "
                    f"{arith['numpy_simd']}, {arith['blas']}) on {when}, load average "
                    f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; regenerate with "
                    f"`python benchmarks/report/regenerate.py {name}`.*\n", "utf-8")
    print(f"published {path}", file=sys.stderr)
    return path


def pending(name: str, command: str, note: str = "") -> Path:
    """The one line a results page shows until ``NAME.md`` is made: the command that makes
    it."""
    path = tables_dir() / f"{name}.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"*Table not yet regenerated: `{command}`{f' ({note})' if note else ''}.*\n",
                    "utf-8")
    return path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("source", nargs="?", help="a Markdown file holding the table")
    ap.add_argument("--name", required=True, help="the table's name (NAME.md)")
    ap.add_argument("--command", help="the command that made (or will make) the table")
    ap.add_argument("--note", default="", help="with --pending: what it costs")
    ap.add_argument("--pending", action="store_true",
                    help="write the not-yet-regenerated line instead")
    args = ap.parse_args()
    if args.pending:
        pending(args.name, args.command or "", args.note)
        return 0
    if not args.source:
        ap.error("a source file, or --pending")
    text = Path(args.source).read_text("utf-8")
    table = "\n".join(line for line in text.splitlines() if line.startswith("|"))
    if not table:
        print(f"publish: {args.source}: no Markdown table in it", file=sys.stderr)
        return 2
    publish(args.name, table, command=args.command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
