"""Mutation testing of the modules where a silent bug changes results (run outside the suite).

``mutmut`` (3.x) derives a module's name from its path, but in this repository the
built-in plugins live in ``plugins/`` and import as ``sitframe.plugins``. So this script
copies the package into a scratch folder laid out as it is installed (``sitframe/``,
``sitframe/plugins/``, ``sitframe/worlds/``, ``tests/``, ``pyproject.toml`` with the
``[tool.mutmut]`` table), runs ``mutmut run`` there on the modules asked for, and prints
``mutmut results``. The per-module test subsets keep a run practical; see README,
"Mutation testing".

Usage::

    nice -n 10 python tools/mutation.py [MODULE ...] [--tests FILE ...] [--workdir DIR]
                                        [--fresh] [--max-children N] [--functions NAME ...]
                                        [--mutants NAME ...]

MODULE is a dotted name as installed (``sitframe.situations.fcm``, ``sitframe.plugins.rewards``);
none = every module of ``[tool.mutmut] only_mutate``. ``--tests`` replaces the test
files of ``pytest_add_cli_args_test_selection`` (a fast subset for the modules asked for).
``--functions`` tests only the mutants of the module-level functions named (e.g.
``compare_logs log_contents`` of ``sitframe.runs.parallel``, whose other code is not in the scope).
``--mutants`` re-tests the mutants named (mutmut's names or patterns), e.g. the survivors of an
earlier run once tests were added (``mutmut`` keeps the other verdicts).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


#: Appended to the scratch copy of ``tests/conftest.py``. mutmut tests each mutant in a
#: process forked from one that already ran the tests, so multiprocessing's forkserver
#: record names a process that is not this one's child: the first worker pool of a
#: mutant's test run (resume, ``--workers``) then fails with ``ChildProcessError`` and
#: every mutant would count as killed. Forgetting that record starts a forkserver of its own.
FORK_RESET = """

def pytest_sessionstart(session):  # (added by tools/mutation.py)
    import multiprocessing.forkserver as mpf

    fs = mpf._forkserver
    if fs._forkserver_pid is not None:
        try:
            os.waitpid(fs._forkserver_pid, os.WNOHANG)
        except ChildProcessError:
            fs._forkserver_pid = fs._forkserver_address = fs._forkserver_alive_fd = None
"""


def build(workdir: Path, fresh: bool, tests: list[str], modules: list[str]) -> None:
    """Copy the sources into ``workdir`` with the installed package layout."""
    if fresh and workdir.exists():
        shutil.rmtree(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    pkg = workdir / "sitframe"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for src, dst in ((ROOT / "sitframe", pkg), (ROOT / "plugins", pkg / "plugins"),
                     (ROOT / "worlds", pkg / "worlds"), (ROOT / "tests", workdir / "tests")):
        if dst.exists():
            shutil.rmtree(dst)
        shutil.copytree(src, dst, ignore=ignore)
    with open(workdir / "tests" / "conftest.py", "a", encoding="utf-8") as f:
        f.write(FORK_RESET)
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    if tests:
        start = text.index("pytest_add_cli_args_test_selection = [")
        end = text.index("]", start) + 1
        text = text[:start] + f"pytest_add_cli_args_test_selection = {tests!r}" + text[end:]
    if modules:  # generate mutants of the modules asked for only
        start = text.index("only_mutate = [")
        end = text.index("]", start) + 1
        files = [m.replace(".", "/") + ".py" for m in modules]
        text = text[:start] + f"only_mutate = {files!r}" + text[end:]
    target = workdir / "pyproject.toml"
    if not target.exists() or target.read_text(encoding="utf-8") != text:
        target.write_text(text.replace("'", '"'), encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("modules", nargs="*", help="dotted module names (default: all configured)")
    ap.add_argument("--workdir", type=Path,
                    default=Path(tempfile.gettempdir()) / "sitframe-mutation")
    ap.add_argument("--tests", nargs="+", default=[], metavar="FILE",
                    help="test files to run against the mutants (default: the configured ones)")
    ap.add_argument("--fresh", action="store_true", help="discard earlier results")
    ap.add_argument("--max-children", type=int, default=None, metavar="N",
                    help="mutants tested at once (default: mutmut's, one per core)")
    ap.add_argument("--functions", nargs="+", default=[], metavar="NAME",
                    help="only the mutants of these module-level functions of the modules")
    ap.add_argument("--mutants", nargs="+", default=[], metavar="NAME",
                    help="re-test only these mutants (names as mutmut prints them)")
    args = ap.parse_args(argv)
    build(args.workdir, args.fresh, args.tests, args.modules)
    mutmut = [sys.executable, "-m", "mutmut"] if shutil.which("mutmut") is None else ["mutmut"]
    names = (args.mutants
             or [f"{m}.x_{fn}__mutmut_*" for m in args.modules for fn in args.functions]
             or [f"{m}.*" for m in args.modules])
    # derandomized property-based tests (as in CI): a mutant's verdict must not depend on
    # which examples a run happens to draw
    env = {**os.environ, "CI": "1"}
    children = [] if args.max_children is None else ["--max-children", str(args.max_children)]
    code = subprocess.call([*mutmut, "run", *children, *names], cwd=args.workdir, env=env)
    subprocess.call([*mutmut, "results"], cwd=args.workdir, env=env)
    return code


if __name__ == "__main__":
    sys.exit(main())
