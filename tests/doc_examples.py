"""Run the examples of README.md and docs/: the blocks, their rules, and a Sybil parser.

Every fenced block of a page is one example; the blocks of a page run in page order, in
a working folder of the page's own (``<pytest tmp>/docs/<page>/``, which starts with the
main job's log, ``logs/obstacle-avoidance.h5``), so a page reads as a session a user types.
What a block is and how it is checked depends on its language:

``python``
    Run in the page's namespace (one per page, shared by its Python blocks, as in a
    notebook); ``assert`` lines are the page's claims.
``pycon``
    A doctest (``>>>`` lines and what they print; ``...`` stands for any text, runs of
    white space are one space) in the same namespace.
``python title="PATH"``, ``toml title="PATH"``
    A file the page writes (a plugin, a config, a sweep file): written to ``PATH`` in the
    working folder; a TOML file must parse.
``toml`` without a title
    A fragment of a config: it must parse, and it is merged into the preset named by
    ``<!-- test: config=PRESET -->`` (default ``obstacle-avoidance``) and validated as a
    config, so every key it shows is one sitframe accepts.
``bash``
    Commands, one a line (``\\`` continues one, ``#`` starts a comment): each must exit 0
    without a traceback. ``sitframe run`` and ``sitframe sweep`` run their trials in this
    process (``--workers 1`` added), and ``sitframe run`` on small settings (``--trials 1
    --iterations 300`` added where the command gives none). The README's install line
    ``python3 -m venv ... && pip install . && COMMAND`` runs its ``COMMAND`` (``.ci/run``
    runs the whole line verbatim in a clean clone).
``console``
    ``$ COMMAND`` lines, each followed by lines that must appear in its output in that
    order (``...`` on a line of its own: any lines; within a line: any text; runs of
    white space are one space). Commands run
    as written (``--workers 1`` added); the exit status is 0 unless the block says
    ``<!-- test: exit=N -->``.
``text`` (or no language)
    Not code: output, diagrams, layouts. ``<!-- test: prints -->`` before one makes it the
    output of the previous block's last command, checked as a console block's output is,
    with every number masked (a learned figure differs on a CPU with other vector
    arithmetic; the README shows the real one), and with it a table cell that holds a
    number or says there is none (``not converged``, ``–``).

``sitframe run obstacle-avoidance`` exactly (the main job) is run once per test session
(:func:`main_job`) and every page that runs it gets that log and output. ``<!-- test:
skip="why" -->`` before a block leaves it out; ``tests/test_doc_examples.py`` counts the
code blocks run and lists those left out with their reasons.
"""

from __future__ import annotations

import contextlib
import doctest
import fcntl
import io
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
#: The pages whose examples run: README.md and every Markdown page under docs/ (the
#: tables under docs/results/tables/ are written by scripts and hold no examples).
PAGE_GLOBS = ("README.md", "docs/**/*.md")
#: Pages whose blocks a test module runs instead of Sybil (it checks the folder they ran
#: in): page -> the test module.
RUN_ELSEWHERE = {"docs/tutorials/plugins.md": "tests/test_docs_plugins.py"}
#: Languages of code blocks (what the share of blocks run is counted over).
CODE = ("python", "pycon", "toml", "bash", "console")
#: Languages of blocks that are not code.
NOT_CODE = ("text", "")
#: The main job, README's first line without its install part.
MAIN_JOB = ("run", "obstacle-avoidance")
#: Small settings for ``sitframe run`` in a bash block.
SMALL = {"--trials": "1", "--iterations": "300"}

_FENCE = re.compile(r"^(?P<indent>[ \t]*)```(?P<lang>[\w-]*)(?P<info>[^\n]*)\n(?P<body>.*?)"
                    r"^(?P=indent)```[ \t]*$", re.MULTILINE | re.DOTALL)
_DIRECTIVE = re.compile(r"<!--\s*test:(?P<args>(?:(?!-->).)*)-->\s*\Z", re.DOTALL)
_INSTALL = re.compile(r"^python3 -m venv .* && pip install [^&]*&& (?P<command>.+)$")


# -- the blocks of a page --------------------------------------------------------------


@dataclass(frozen=True)
class Block:
    """One fenced block of a page."""

    page: str  # path relative to the repository
    line: int  # 1-based line of the opening fence
    lang: str
    title: str | None
    text: str
    directive: dict[str, str]
    start: int  # character offsets in the page
    end: int

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"

    @property
    def is_code(self) -> bool:
        return self.lang in CODE

    @property
    def skip(self) -> str | None:
        return self.directive.get("skip")


def _directive(before: str) -> dict[str, str]:
    """The ``<!-- test: k=v ... -->`` comment that ends ``before`` (the text up to a fence)."""
    m = _DIRECTIVE.search(before[-500:])
    if m is None:
        return {}
    out = {}
    for word in shlex.split(m.group("args")):
        key, _, value = word.partition("=")
        out[key] = value
    return out


def blocks(text: str, page: str) -> list[Block]:
    """The fenced blocks of a page's ``text``."""
    out = []
    for m in _FENCE.finditer(text):
        title = re.search(r'title="([^"]*)"', m.group("info"))
        indent = len(m.group("indent"))
        body = "".join(line[indent:] if line[:indent].isspace() else line
                       for line in m.group("body").splitlines(keepends=True))
        out.append(Block(page, text.count("\n", 0, m.start()) + 1, m.group("lang"),
                         title.group(1) if title else None, body,
                         _directive(text[:m.start()]), m.start(), m.end()))
    return out


def pages() -> list[Path]:
    """Every page whose examples run."""
    found: list[Path] = []
    for pattern in PAGE_GLOBS:
        found += sorted(ROOT.glob(pattern))
    return [p for p in found if "results/tables" not in p.as_posix()]


# -- what one command did ----------------------------------------------------------------


@dataclass
class Outcome:
    """What one command did."""

    argv: list[str]
    code: int
    out: str
    err: str


@dataclass
class Page:
    """The state of one page as its blocks run: its folder, namespace and commands."""

    root: Path
    namespace: dict[str, Any] = field(default_factory=dict)
    commands: list[Outcome] = field(default_factory=list)
    pythonpath: list[str] = field(default_factory=list)
    main_job: tuple[Path, Outcome] | None = None

    @contextlib.contextmanager
    def inside(self) -> Iterator[None]:
        """In the page's folder, with sitframe's user-facing environment."""
        old_cwd = Path.cwd()
        saved = {k: os.environ.pop(k) for k in
                 ("SITFRAME_TRACEBACK", "SITFRAME_DISABLE_PLUGIN_AUTOLOAD") if k in os.environ}
        os.chdir(self.root)
        try:
            yield
        finally:
            os.chdir(old_cwd)
            os.environ.update(saved)

    # -- commands ------------------------------------------------------------------------
    def sitframe(self, argv: list[str]) -> Outcome:
        if list(argv) == list(MAIN_JOB) and self.main_job is not None:
            log, outcome = self.main_job  # the session's run of exactly this command
            (self.root / "logs").mkdir(exist_ok=True)
            shutil.copyfile(log, self.root / "logs" / log.name)
            return Outcome(argv, outcome.code, outcome.out, outcome.err)
        if self.pythonpath:  # after an (emulated) pip install: a fresh interpreter
            env = {k: v for k, v in os.environ.items()
                   if k not in ("SITFRAME_TRACEBACK", "SITFRAME_DISABLE_PLUGIN_AUTOLOAD")}
            env["PYTHONPATH"] = os.pathsep.join(self.pythonpath)
            proc = subprocess.run(
                [sys.executable, "-c", "import sys; from sitframe.cli import main; "
                 "sys.exit(main())", *argv], cwd=self.root, env=env, capture_output=True,
                text=True, timeout=300)
            return Outcome(argv, proc.returncode, proc.stdout, proc.stderr)
        return run_in_process(argv)

    def pip_install_editable(self, project: str) -> Outcome:
        """Install ``project`` the way ``pip install -e`` makes it visible to importlib.metadata
        (a ``.dist-info`` folder on a path of this page's own; nothing is downloaded and the
        virtualenv is not touched)."""
        root = (self.root / project).resolve()
        meta = tomllib.loads((root / "pyproject.toml").read_text())["project"]
        site = self.root / ".site"
        dist = site / f"{meta['name'].replace('-', '_')}-{meta['version']}.dist-info"
        dist.mkdir(parents=True)
        (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {meta['name']}\n"
                                       f"Version: {meta['version']}\n")
        lines = []
        for group, eps in meta.get("entry-points", {}).items():
            lines.append(f"[{group}]")
            lines += [f"{name} = {value}" for name, value in eps.items()]
        (dist / "entry_points.txt").write_text("\n".join(lines) + "\n")
        self.pythonpath = [str(site), str(root)]
        return Outcome(["pip", "install", "-e", project], 0, "", "")

    def shell(self, line: str) -> Outcome:
        proc = subprocess.run(["bash", "-c", line], cwd=self.root, capture_output=True,
                              text=True, timeout=60)
        return Outcome(shlex.split(line), proc.returncode, proc.stdout, proc.stderr)

    def run_command(self, line: str, *, small: bool) -> Outcome:
        install = _INSTALL.match(line)
        if install:
            line = install.group("command")
        argv = shlex.split(line, comments=True)
        if argv[0] == "sitframe":
            return self.sitframe(_settings(argv[1:], small=small))
        if argv[:3] == ["pip", "install", "-e"] and len(argv) == 4:
            return self.pip_install_editable(argv[3])
        if argv[0] in ("mkdir", "cp", "touch", "ls", "cat", "rm"):
            return self.shell(line)
        raise AssertionError(f"the page runs a command the tests cannot: {line!r}")


def run_in_process(argv: list[str]) -> Outcome:
    """``sitframe ARGV`` in this process (:func:`sitframe.cli.main`), output captured."""
    from sitframe.cli import main

    out, err = io.StringIO(), io.StringIO()
    # as when piped: no COLUMNS (a test process may carry one), so tables print whole
    columns = os.environ.pop("COLUMNS", None)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(list(argv))
    finally:
        if columns is not None:
            os.environ["COLUMNS"] = columns
    return Outcome(list(argv), code, out.getvalue(), err.getvalue())


def _settings(argv: list[str], *, small: bool) -> list[str]:
    """``argv`` with trials in this process, and ``run`` small if ``small``."""
    argv = list(argv)
    i, cmd = len(argv), ""
    k = 0
    while k < len(argv):  # the subcommand: the first word that is not a global option
        if argv[k] == "--plugins-dir":
            k += 2
        elif argv[k].startswith("-"):
            k += 1
        else:
            i, cmd = k, argv[k]
            break
    if cmd in ("run", "sweep") and argv[i:] != list(MAIN_JOB) \
            and not {"--workers", "--scheduler"} & set(argv):
        argv += ["--workers", "1"]
    if small and cmd == "run" and "--resume" not in argv and argv[i:] != list(MAIN_JOB):
        for option, value in SMALL.items():
            if option not in argv:
                argv += [option, value]
    return argv


def commands(text: str) -> list[str]:
    """The command lines of a bash block (``\\`` joins lines; blank and comment lines go)."""
    joined = re.sub(r"\\\n\s*", " ", text)
    return [line.strip() for line in joined.splitlines()
            if line.strip() and not line.strip().startswith("#")]


def console_steps(block: Block) -> list[tuple[str, list[str]]]:
    """``(command, expected output lines)`` of a console block."""
    steps: list[tuple[str, list[str]]] = []
    for line in block.text.splitlines():
        if line.startswith("$ "):
            steps.append((line[2:], []))
        elif line.strip():
            assert steps, f"{block.where}: output before a command"
            steps[-1][1].append(line)
    return steps


# -- comparing output --------------------------------------------------------------------

_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?")
#: A table cell that stands for a number a run may or may not have: a trial's "converged at"
#: and its collisions after convergence ("not converged", "–"), masked with the numbers.
_NO_NUMBER = re.compile(r"(?<=│ )(?:not converged|–)(?= │)")
_RULE = re.compile(r"([━─═┄]+)")


def _norm(line: str, *, numbers: bool = False) -> str:
    line = " ".join(line.split())
    if numbers:
        line = _RULE.sub(lambda m: m.group(1)[0], _NUMBER.sub("N", _NO_NUMBER.sub("N", line)))
    return line


def _matcher(want: str, numbers: bool) -> re.Pattern[str]:
    """A line of expected output as a pattern: ``...`` within it stands for any text."""
    parts = _norm(want, numbers=numbers).split("...")
    return re.compile(".*".join(re.escape(p) for p in parts))


def in_order(expected: list[str], output: str, where: str, *, numbers: bool = False) -> None:
    """Each expected line (``...`` alone = any lines; within a line = any text) is a line
    of ``output``, in order."""
    lines = [_norm(x, numbers=numbers) for x in output.splitlines()]
    i = 0
    for want in expected:
        if want.strip() == "...":
            continue
        w = _matcher(want, numbers)
        while i < len(lines) and not w.fullmatch(lines[i]):
            i += 1
        assert i < len(lines), f"{where}: expected the line {want!r} in:\n{output}"
        i += 1


# -- running a block ---------------------------------------------------------------------


def check(res: Outcome, code: int, where: str) -> None:
    assert res.code == code, f"{where}: exit {res.code}, expected {code}\n{res.out}\n{res.err}"
    assert "Traceback" not in res.out + res.err, f"{where}:\n{res.err}"


def run_block(page: Page, block: Block) -> None:
    """Run one block of ``page`` as its language says (see the module docstring)."""
    with page.inside():
        if block.title is not None:
            path = page.root / block.title
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(block.text)
            if block.lang == "toml":
                tomllib.loads(block.text)
        elif block.lang == "python":
            code = compile(block.text, block.where, "exec")
            with contextlib.redirect_stdout(io.StringIO()):
                exec(code, page.namespace)  # noqa: S102 - the page's own example
        elif block.lang == "pycon":
            _doctest(page, block)
        elif block.lang == "toml":
            _config_fragment(block)
        elif block.lang == "bash":
            for line in commands(block.text):
                res = page.run_command(line, small=True)
                page.commands.append(res)
                check(res, 0, f"{block.where}: {line}")
        elif block.lang == "console":
            code = int(block.directive.get("exit", "0"))
            for command, expected in console_steps(block):
                res = page.run_command(command, small=False)
                page.commands.append(res)
                where = f"{block.where}: $ {command}"
                check(res, code if command.startswith("sitframe") else 0, where)
                in_order(expected, res.out + res.err, where)
        elif "prints" in block.directive:
            assert page.commands, f"{block.where}: prints, but no command ran before it"
            last = page.commands[-1]
            in_order(block.text.splitlines(), last.out + last.err, block.where, numbers=True)


def _doctest(page: Page, block: Block) -> None:
    parser = doctest.DocTestParser()
    test = parser.get_doctest(block.text, page.namespace, block.where, block.page, block.line)
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    runner = doctest.DocTestRunner(optionflags=flags)
    out = io.StringIO()
    runner.run(test, out=out.write, clear_globs=False)
    page.namespace.update(test.globs)  # (a DocTest runs in a copy of the namespace)
    assert not runner.failures, out.getvalue()


def _config_fragment(block: Block) -> None:
    from sitframe.config import preset_text, validate_config

    fragment = tomllib.loads(block.text)
    base = tomllib.loads(preset_text(block.directive.get("config", "obstacle-avoidance")))
    validate_config(_merge(base, fragment), file=block.where)


def _merge(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in extra.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) \
            else v
    return out


# -- the main job, once per session ------------------------------------------------------


def main_job(shared: Path) -> tuple[Path, Outcome]:
    """``sitframe run obstacle-avoidance`` (trials in this process), once for all test
    processes that share ``shared``: ``(log, outcome)``."""
    folder = shared / "main-job"
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / "logs" / "obstacle-avoidance.h5"
    with open(shared / "main-job.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        saved = folder / "outcome.txt"
        if not saved.exists():
            page = Page(folder)
            with page.inside():
                res = run_in_process([*MAIN_JOB, "--workers", "1"])
            check(res, 0, "the main job")
            saved.write_text(f"{res.code}\n{len(res.out)}\n{res.out}{res.err}")
        code, n, rest = saved.read_text().split("\n", 2)
    return log, Outcome(list(MAIN_JOB), int(code), rest[:int(n)], rest[int(n):])


# -- Sybil -------------------------------------------------------------------------------


class Parser:
    """The Sybil parser: one region per block that runs (skipped blocks give none)."""

    def __call__(self, document: Any) -> Iterator[Any]:
        from sybil import Region

        page = Path(document.path).resolve().relative_to(ROOT).as_posix()
        for block in blocks(document.text, page):
            if block.skip is not None:
                continue
            if block.lang in CODE or "prints" in block.directive:
                yield Region(block.start, block.end, block, _evaluate)


def _evaluate(example: Any) -> None:
    page = example.namespace.get("__page__")
    if page is None:  # the first example of the page: its folder, with the main job's log
        env = example.namespace["doc_env"]
        name = Path(example.path).resolve().relative_to(ROOT).with_suffix("").as_posix()
        root = env["base"] / "docs" / name.replace("/", "-")
        root.mkdir(parents=True)
        log, outcome = env["main_job"]
        (root / "logs").mkdir()
        shutil.copyfile(log, root / "logs" / log.name)
        page = Page(root, namespace={"__name__": "__doc__"}, main_job=(log, outcome))
        example.namespace["__page__"] = page
    run_block(page, example.parsed)


def sybil() -> Any:
    """The Sybil that collects README.md and the docs pages (see the root conftest.py)."""
    from sybil import Sybil

    return Sybil(parsers=[Parser()], patterns=["README.md", "docs/*.md", "docs/*/*.md",
                                               "docs/*/*/*.md"],
                 excludes=["docs/results/tables/*.md", *RUN_ELSEWHERE], path=str(ROOT),
                 fixtures=["doc_env"])
