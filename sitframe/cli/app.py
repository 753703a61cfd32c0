"""The ``sitframe`` command line.

::

    sitframe run EXPERIMENT [--trials N] [--seed S] [--world W] [--iterations L]
                            [--out LOG] [--clusters-from LOG] [--json]
                            [--workers K | --scheduler ADDRESS]
    sitframe run --resume LOG [--workers K | --scheduler ADDRESS] [--json]
    sitframe evaluate LOG --world W [--trial K] [--iterations N] [--seed S] [--json]
                      [--goal-episodes N [--arbiter NAME] [--fusion CONFIG]]
    sitframe world show W [-o PNG]
    sitframe world list
    sitframe presets
    sitframe plugins
    sitframe sweep SWEEP.toml [--workers K | --scheduler ADDRESS] [--out DIR] [--json]
    sitframe pack LOG

Trials run in a local process pool (``--workers``, default one per core;
``--workers 1`` runs them in this process, the only mode in which
per-iteration ``sitframe_step`` observers fire) or on a Dask cluster
(``--scheduler``); results are bit-identical either way and one process
writes the log. A killed run's log keeps every finished trial and
``run --resume LOG`` finishes it.

Errors caused by input (config, world, log, plugin) print one line on stderr
(``sitframe: error: FILE: KEY: what was wrong; what was expected``) and exit
with status 2, before anything is written. Plugin code that raises, or returns
a value that breaks the contract, during a run prints one line naming the
plugin, component, method, trial and iteration and exits with status 3; the
log keeps every finished trial and is marked ``failed``. Set
``SITFRAME_TRACEBACK=1`` to see the traceback as well. Ctrl-C exits with status
130 and SIGTERM with 143, each after marking the log ``aborted`` (``run --resume
LOG`` finishes it).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pkgutil
import signal
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Any

from sitframe import __version__
from sitframe import params as P
from sitframe.errors import (
    PLUGIN_FAULT_EXIT,
    InputError,
    PluginError,
    PluginFault,
    forget_notes,
    note,
    quiet_teardown,
    show_warning,
    warn,
)

# start-up time: this module is imported whenever the command line builds its parser
# (``sitframe --help`` and every command), so what only one command needs is imported
# inside the function that needs it.


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse's own convention)
        self.exit(2, f"{self.prog}: error: {message}\n")


class _Formatter(argparse.HelpFormatter):
    """argparse's formatter, but an example (an epilog starting ``example``) and the
    grouped command list keep their lines as written."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if text.startswith(("example", "commands")):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


#: The commands as ``sitframe --help`` groups them: what a user does with each.
COMMAND_GROUPS: dict[str, tuple[str, ...]] = {
    "run": ("run", "sweep", "evaluate", "pack"),
    "analyse": ("analyse", "compare", "export", "replay"),
    "inspect": ("presets", "world", "plugins"),
}

#: The example that ends each command's help (tested: each one parses).
EXAMPLES: dict[str, str] = {
    "run": "sitframe run obstacle-avoidance --trials 3 --seed 1 --out logs/oa.h5",
    "sweep": "sitframe sweep sweeps/ablation.toml --workers 2",
    "evaluate": "sitframe evaluate logs/obstacle-avoidance.h5 --world novel-1 --trial 3 --json",
    "pack": "sitframe pack logs/obstacle-avoidance.h5",
    "analyse": "sitframe analyse logs/obstacle-avoidance.h5 -o report",
    "compare": "sitframe compare logs/a.h5 logs/b.h5",
    "export": "sitframe export logs/obstacle-avoidance.h5 --format parquet",
    "replay": "sitframe replay logs/obstacle-avoidance.h5 --trial 2 -o trial2.gif",
    "presets": "sitframe presets",
    "world": "sitframe world show training -o training.png",
    "world show": "sitframe world show novel-1 -o novel-1.png",
    "world list": "sitframe world list",
    "plugins": "sitframe --plugins-dir myplugins plugins",
}


def _example(command: str) -> str:
    return f"example:\n  {EXAMPLES[command]}"


def _command_list(helps: dict[str, str]) -> str:
    """The grouped list of commands that ``sitframe --help`` shows."""
    lines = ["commands to learn robot behaviours over fuzzy situations and read the logs",
             "(`sitframe COMMAND -h` shows a command's options and an example):"]
    for group, names in COMMAND_GROUPS.items():
        lines.append(f"  {group}:")
        lines += [f"    {name:<10}{helps[name]}" for name in names]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """The ``sitframe`` argument parser: its commands grouped (:data:`COMMAND_GROUPS`),
    each command's help ending with an example (:data:`EXAMPLES`)."""
    p = _Parser(prog="sitframe", formatter_class=_Formatter,
                usage="%(prog)s [-h] [--version] [--plugins-dir DIR] COMMAND ...")
    p.add_argument("--version", action="version", version=f"sitframe {__version__}")
    p.add_argument("--plugins-dir", action="append", default=[], metavar="DIR",
                   help="load loose *.py plugin modules from DIR (repeatable)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser,
                           metavar="COMMAND", help=argparse.SUPPRESS)  # listed, grouped, above
    helps: dict[str, str] = {}

    def command(name: str, help_text: str, **kw: Any) -> argparse.ArgumentParser:
        helps[name] = help_text
        return sub.add_parser(name, help=help_text, epilog=_example(name),
                              formatter_class=_Formatter, **kw)

    r = command("run", "run an experiment (a preset name or a TOML config)")
    r.add_argument("experiment", nargs="?",
                   help="preset name (see `sitframe presets`) or path to a .toml")
    r.add_argument("--trials", type=int, metavar="N", help="number of learning trials")
    r.add_argument("--seed", type=int, metavar="S",
                   help="run seed (trial seeds are derived from it)")
    r.add_argument("--world", metavar="W", help="learning world (shipped name or .toml path)")
    r.add_argument("--iterations", type=int, metavar="L", help="iterations per trial (l)")
    r.add_argument("--out", metavar="LOG", help="HDF5 log path (default logs/<name>.h5). A log "
                   "already there is kept until this run has finished a trial of its own, then "
                   "replaced; a run that fails or is stopped before keeps it as it was. A "
                   "symbolic link is followed: the log is written where it points")
    r.add_argument("--clusters-from", metavar="LOG",
                   help="reuse the fitted situations of LOG (skips collect and cluster)")
    r.add_argument("--json", action="store_true", help="print machine-readable results")
    add_parallel_arguments(r)
    r.add_argument("--resume", metavar="LOG",
                   help="finish the unfinished run logged in LOG (config, seed and situations "
                   "come from the log; only the missing trials run)")

    e = command("evaluate", "run a log's frozen rule base in a world")
    e.add_argument("log", help="HDF5 log written by `sitframe run`")
    e.add_argument("--world", required=True, metavar="W", help="world to evaluate in")
    e.add_argument("--trial", type=int, default=0, metavar="K",
                   help="which learning trial's policy (default 0)")
    e.add_argument("--iterations", type=int, default=1000, metavar="N",
                   help="iterations of the frozen run (default 1000)")
    e.add_argument("--seed", type=int, default=0, metavar="S",
                   help="seed of the evaluation (default 0)")
    e.add_argument("--goal-episodes", type=int, metavar="N",
                   help="run N random goal episodes: the log's learned rule base fused with "
                   "goal finding (see --fusion)")
    e.add_argument("--arbiter", metavar="NAME",
                   help="arbiter to use instead of the config's (e.g. cdb, priority)")
    e.add_argument("--fusion", default="goal-finding", metavar="CONFIG",
                   help="preset or TOML whose behaviours, arbiter and [goal] table the goal "
                   "episodes use (default: goal-finding)")
    e.add_argument("--json", action="store_true", help="print the figures as JSON")
    e.add_argument("--per-episode", action="store_true",
                   help="with --goal-episodes: also every episode's figures (per_episode)")

    w = command("world", "list or draw the shipped worlds (or a world file)")
    wsub = w.add_subparsers(dest="world_command", required=True, parser_class=_Parser,
                            metavar="{show,list}")
    ws = wsub.add_parser("show", help="draw a world to a PNG", epilog=_example("world show"),
                         formatter_class=_Formatter)
    ws.add_argument("world", help="shipped name or .toml path")
    ws.add_argument("-o", "--output", metavar="PNG", help="PNG path (default <name>.png)")
    wsub.add_parser("list", help="list the shipped worlds", epilog=_example("world list"),
                    formatter_class=_Formatter)

    command("presets", "list the shipped experiment presets")
    command("plugins", "list the plugins found and the components they register").add_argument(
        "--tables", action="store_true",
        help="print the config tables the plugins declare (keys, types, defaults, ranges) "
             "as Markdown")
    for name, module in EXTRA_COMMANDS.items():
        mod = pkgutil.resolve_name(module)
        sp = command(name, mod.HELP, description=mod.__doc__)
        mod.add_arguments(sp)
    p.description = _command_list(helps)
    return p


#: Subcommands implemented elsewhere: name -> module (or ``module:Class``) with ``HELP``,
#: ``add_arguments(parser)`` and ``main(args) -> int`` (exit status).
EXTRA_COMMANDS: dict[str, str] = {"analyse": "sitframe.cli.logs:Analyse",
                                  "replay": "sitframe.cli.logs:Replay",
                                  "compare": "sitframe.cli.logs:Compare",
                                  "export": "sitframe.cli.logs:Export",
                                  "sweep": "sitframe.cli.sweep", "pack": "sitframe.cli.pack"}


#: Commands that read a log given on the command line: an exception while they use its
#: contents means the log is damaged (valid HDF5, wrong layout), reported in one line.
_LOG_READERS = ("evaluate", "analyse", "replay", "export", "pack")


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv``; returns the exit status.

    0 success, 2 bad input (config, world, log, a plugin that cannot load or
    breaks the protocol at creation), 3 plugin code failed during the run
    (:class:`~sitframe.errors.PluginFault`: the log keeps every finished trial
    and says ``failed``), 130 Ctrl-C, 143 SIGTERM (the run is marked
    ``aborted`` in both cases), 141 when stdout is closed early (``| head``;
    quietly).
    """
    from sitframe.logs.interrupts import Terminated, terminate_as_interrupt
    from sitframe.logs.writer import unlock_log

    args = None
    forget_notes()
    try:
        with terminate_as_interrupt(), warnings.catch_warnings():
            warnings.showwarning = show_warning
            args = build_parser().parse_args(argv)
            P.check_environment()  # (a bad variable: one line before any work)
            return _dispatch(args)
    except (InputError, PluginError) as exc:
        if os.environ.get("SITFRAME_TRACEBACK"):
            raise
        print(f"sitframe: error: {' '.join(str(exc).splitlines())}", file=sys.stderr)
        return PLUGIN_FAULT_EXIT if isinstance(exc, PluginFault) else 2
    except KeyboardInterrupt as exc:
        terminated = isinstance(exc, Terminated)
        print(f"sitframe: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
        return 143 if terminated else 130
    except BrokenPipeError:
        _silence_stdout()
        return 141
    except (KeyError, IndexError, ValueError, TypeError, AttributeError) as exc:
        log = getattr(args, "log", None)
        if os.environ.get("SITFRAME_TRACEBACK") or getattr(args, "command", None) \
                not in _LOG_READERS or not log:
            raise
        msg = " ".join(str(exc).split()) or type(exc).__name__
        err = InputError(f"the log's contents are damaged or not laid out as a sitframe log "
                         f"({type(exc).__name__}: {msg})", file=log)
        print(f"sitframe: error: {err}", file=sys.stderr)
        return 2
    finally:
        unlock_log()  # every log this process was writing: the run is over


def _silence_stdout() -> None:
    """Point stdout at /dev/null (its reader went away; flushing it at exit would fail)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # not a real file (e.g. captured in tests)
        pass


def console_main(argv: list[str] | None = None) -> int:
    """The ``sitframe`` console script: :func:`main`, then exit without being interruptible.

    Once :func:`main` has returned, the log is complete (or marked aborted);
    a Ctrl-C or SIGTERM that arrives while the interpreter shuts the worker
    pool down would otherwise kill the process by the signal itself (status
    -2 or -15, as if nothing had been written), so both are ignored from
    here on.
    """
    quiet_teardown()
    status = main(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        sys.stdout.flush()  # now, not at exit, where a closed pipe prints a traceback
    except BrokenPipeError:
        _silence_stdout()
        return 141
    return status


def _dispatch(args: argparse.Namespace) -> int:
    cmd = args.command
    if cmd == "run":
        return cmd_run(args)
    if cmd == "evaluate":
        return cmd_evaluate(args)
    if cmd == "world":
        return cmd_world(args)
    if cmd == "presets":
        return cmd_presets()
    if cmd == "plugins":
        return cmd_plugins(args)
    if cmd in EXTRA_COMMANDS:
        return int(pkgutil.resolve_name(EXTRA_COMMANDS[cmd]).main(args))
    raise AssertionError(cmd)  # pragma: no cover - argparse enforces the choices


def _count(name: str, value: int | None, hi: int | None = None, lo: int = 1) -> None:
    if value is not None:
        P.number(f"--{name}", value, lo=lo, hi=hi, integer=True)


# ---------------------------------------------------------------------------
# run
# ---------------------------------------------------------------------------


def add_parallel_arguments(parser: argparse.ArgumentParser) -> None:
    """``--workers`` and ``--scheduler`` (shared by ``run`` and ``sweep``)."""
    parser.add_argument("--workers", type=int, metavar="K",
                        help="run trials in K local processes (default: the number of CPU "
                        "cores; 1 = serially in this process, the only mode in which "
                        "per-iteration observers fire)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run trials on the Dask distributed cluster at ADDRESS "
                        "(e.g. tcp://host:8786; needs the 'dask' extra)")


def cmd_run(args: argparse.Namespace) -> int:
    from sitframe.runs.parallel import make_executor

    if args.resume:
        return _run_resume(args)
    if not args.experiment:
        raise InputError("missing EXPERIMENT (a preset name or a .toml config), or give "
                         "--resume LOG", key="run")
    exp, kwargs = _prepare_run(args)
    n_tasks = exp.info.n_trials if "learn" in exp.config.experiment.stages else 0
    exp.executor = make_executor(args.workers, args.scheduler, n_tasks)
    result = _execute(exp, kwargs, replacing=True)
    if args.json:
        print(json.dumps(run_json(result), indent=2, default=_json_default))
    else:
        print_run(result)
    return 0


def _claim(out: str, *, replacing: bool = False, key: str = "--out") -> None:
    """Become the log's only writer now (refused, one line, if another process is); with
    ``replacing``, say on stderr that an existing log will be replaced (only once the new
    run has a trial of its own: :meth:`sitframe.logs.writer.LogWriter.start`)."""
    from sitframe.logs.reader import open_log
    from sitframe.logs.writer import lock_log

    lock_log(out, key)
    if replacing and Path(out).is_file():
        try:
            what = f"the existing log (status {open_log(out).status})"
        except InputError:
            what = "the existing file (not a readable sitframe log)"
        note(f"{out}: replacing {what} once this run has finished a trial of its own; until "
             "then it is kept as it is")


def _execute(exp: Any, kwargs: dict[str, Any], *, replacing: bool = False,
             key: str = "--out") -> Any:
    """Claim the log (:func:`_claim`), ``exp.run(**kwargs)``, releasing the executor's
    workers however it ends."""
    for msg in getattr(exp.pm, "sitframe_clashes", []):
        warn(msg)
    failed = True
    try:
        _claim(exp.out, replacing=replacing, key=key)
        result = exp.run(**kwargs)
        failed = False
        return result
    finally:
        shutdown = getattr(exp.executor, "shutdown", None)
        if shutdown is not None:
            shutdown(cancel=failed)


def _run_resume(args: argparse.Namespace) -> int:
    from sitframe.runs.parallel import make_executor
    from sitframe.runs.prepare import prepare_resume

    if args.experiment:
        raise InputError("give either EXPERIMENT or --resume LOG, not both (the log's config "
                         "is used)", key="--resume")
    for opt in ("trials", "seed", "world", "iterations", "out", "clusters_from"):
        if getattr(args, opt) is not None:
            raise InputError("cannot be combined with --resume (the log's config is used)",
                             key=f"--{opt.replace('_', '-')}")
    exp, kwargs, missing = prepare_resume(args.resume, plugins_dirs=tuple(args.plugins_dir),
                                          progress=not args.json and sys.stderr.isatty())
    from sitframe.logs.reader import open_log

    if not missing and open_log(args.resume).complete:
        if args.json:
            print(json.dumps({"log": args.resume, "status": "complete", "resumed_trials": [],
                              "trials": []}, indent=2))
        else:
            print(f"{args.resume}: already complete; nothing to resume")
        return 0
    if exp.info.extra.get("code_changed"):
        warn(f"{args.resume}: the code of sitframe or its plugins changed since this run "
             "started; the resumed trials may differ from the logged ones")
    exp.executor = make_executor(args.workers, args.scheduler, len(missing))
    result = _execute(exp, kwargs, key="--resume")
    if args.json:
        doc = run_json(result)
        doc["resumed_trials"] = missing
        print(json.dumps(doc, indent=2, default=_json_default))
    else:
        print(f"resumed {args.resume}: ran trial(s) {missing or 'none'}")
        print_run(result)
    return 0


def _prepare_run(args: argparse.Namespace) -> tuple[Any, dict[str, Any]]:
    from sitframe.contract.config import load_config
    from sitframe.runs.parallel import make_executor
    from sitframe.runs.prepare import make_prerequisites, prepare_experiment

    _count("trials", args.trials)
    _count("iterations", args.iterations)
    _count("seed", args.seed, lo=0)
    cfg, source, base_dir = load_config(args.experiment, plugin_folders=bool(args.plugins_dir))
    e = cfg["experiment"]
    for key in ("trials", "seed", "world", "iterations", "clusters_from"):
        val = getattr(args, key)
        if val is not None:  # (paths on the command line are relative to the working folder)
            e[key] = _abspath(val) if key in ("world", "clusters_from") else val
    if args.out is not None and not args.out.strip():  # (was the default path, silently)
        raise InputError(f"expected the path of the log to write, got {args.out!r}",
                         key="--out")
    out = args.out or str(Path("logs") / f"{e['name']}.h5")
    with _options_blamed(args, e):
        make_prerequisites(cfg, base_dir,
                           executor_for=partial(make_executor, args.workers, args.scheduler),
                           plugins_dirs=tuple(args.plugins_dir),
                           progress=not args.json and sys.stderr.isatty(), say=note)
        exp, kwargs = prepare_experiment(cfg, source=source, base_dir=base_dir, out=out,
                                         plugins_dirs=tuple(args.plugins_dir),
                                         progress=not args.json and sys.stderr.isatty())
    exp.needs_clusters(kwargs.get("interpreter_state"))  # stages that cannot run: fail now
    return exp, kwargs


#: ``run`` options that set a key of the config's ``[experiment]`` table.
_OVERRIDES = ("trials", "seed", "world", "iterations", "clusters_from")


@contextmanager
def _options_blamed(args: argparse.Namespace, e: dict[str, Any]) -> Iterator[None]:
    """An input error about a value given on the command line names the option (``--seed``),
    not the config key it overrode (which the config file may not even hold); a log named
    by ``--clusters-from`` that cannot be used names the option too."""
    given = {f"experiment.{k}": f"--{k.replace('_', '-')}" for k in _OVERRIDES
             if getattr(args, k) is not None}
    try:
        yield
    except InputError as exc:
        option = given.get(exc.key or "")
        if option is not None:
            raise InputError(exc.message, key=option) from None
        if args.clusters_from is not None and exc.key is None and \
                exc.file == e.get("clusters_from"):
            raise InputError(exc.message, file=exc.file, key="--clusters-from") from None
        raise


def _abspath(path: str) -> str:
    """A command-line path made absolute (config paths resolve against the config's folder);
    shipped names (no '/', no .toml) stay as they are."""
    p = Path(path)
    return str(p.absolute()) if (p.suffix in (".toml", ".h5") or len(p.parts) > 1) else path


def _json_default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def _finite(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def run_json(result: Any) -> dict[str, Any]:
    """The ``run --json`` document (keys are a contract; docs/reference/json.md)."""
    from sitframe.contract.records import summary_key  # (light; the parser never needs it)

    trials, head = [], summary_key("eval", "")
    # (the run's number of situations; an evolving interpreter's trials each report their own)
    situations = len(result.interpreter_state.get("centers", ()))
    for tr in result.trials:
        s = tr.summary
        rule_base = {f"{label}.{out}": [float(v) for v in o.values()]
                     for label, pol in tr.policies.items() for out, o in pol.outputs.items()}
        entry = {
            "trial": tr.index,
            "seed": tr.seed,
            "converged": bool(s["converged"]),
            "convergence_iteration": (int(s["convergence_iteration"])
                                      if s["converged"] else None),
            "collisions_per_1000_after_convergence":
                _finite(s["collisions_per_1000_after_convergence"]),
            "rule_base": rule_base,
            "collisions": s["collisions"],
            "collisions_per_1000": _finite(s["collisions_per_1000"]),
            "coverage": _finite(s["coverage"]),
            "situations": int(s.get("situations", situations)),
            "evaluation": {k[len(head):]: _finite(v) for k, v in s.items() if k.startswith(head)},
        }
        trials.append(entry)
    return {"log": result.info.out, "wall_seconds": round(result.wall_seconds, 3),
            "status": result.status, "trials": trials}


def print_run(result: Any) -> None:
    from rich.console import Console
    from rich.table import Table

    # Piped or redirected (no terminal, no COLUMNS), rich would cut the tables to 80
    # columns, and a wide rule-base table (a learned arbiter has two columns per
    # context) would reach the file as ellipses; there, print the table at full width.
    wide = not sys.stdout.isatty() and "COLUMNS" not in os.environ
    console = Console(width=1000 if wide else None)
    t = Table(title=f"{result.info.name}: {len(result.trials)} trials "
              f"in {result.wall_seconds:.1f} s")
    for col in ("trial", "converged at", "collisions", "coll./1000 after conv.", "coverage"):
        t.add_column(col, justify="right")
    for tr in result.trials:
        s = tr.summary
        t.add_row(str(tr.index),
                  str(s["convergence_iteration"]) if s["converged"] else "not converged",
                  str(s["collisions"]),
                  f"{s['collisions_per_1000_after_convergence']:.1f}" if s["converged"]
                  else "–",  # (nothing after: it learnt to the end of its budget)
                  f"{s['coverage']:.2f}")
    console.print(t)
    if result.trials:
        from sitframe.runs.evaluation import rule_base_table

        for space in ("default", *result.info.config.get("spaces", {})):
            console.print(rule_base_table(result, space))
    if result.info.out:
        console.print(f"log: {result.info.out}")


# ---------------------------------------------------------------------------
# evaluate
# ---------------------------------------------------------------------------


def cmd_evaluate(args: argparse.Namespace) -> int:
    from sitframe.contract.config import MAX_ITERATIONS, MAX_TRIALS
    from sitframe.runs.evaluation import evaluate_log

    _count("iterations", args.iterations, MAX_ITERATIONS)
    _count("goal-episodes", args.goal_episodes, MAX_TRIALS)
    _count("seed", args.seed, lo=0)
    summary = evaluate_log(args.log, world=args.world, trial=args.trial,
                           iterations=args.iterations, seed=args.seed,
                           plugins_dirs=tuple(args.plugins_dir),
                           goal_episodes=args.goal_episodes or 0, arbiter=args.arbiter,
                           fusion=args.fusion, per_episode=args.per_episode)
    doc = {k: _finite(v) for k, v in summary.items()}
    if args.json:
        print(json.dumps(doc, indent=2, default=_json_default))
    else:
        for k, v in doc.items():
            if k == "spaces":  # one line per situation space: what it is and who reads it
                for name, sp in v.items():
                    print(f"{'space ' + name:>22}: {sp['situations']} situations over readings "
                          f"{sp['view']}, read by {', '.join(sp['read_by']) or 'none'}")
                continue
            print(f"{k:>22}: {v}")
    return 0


# ---------------------------------------------------------------------------
# world, presets, plugins
# ---------------------------------------------------------------------------


def cmd_world(args: argparse.Namespace) -> int:
    from sitframe.sim.world import list_worlds, load_world

    if args.world_command == "list":
        for name in list_worlds():
            w = load_world(name)
            print(f"{name:16} {w.description}")
        return 0
    world = load_world(args.world)
    out = Path(args.output or f"{world.name}.png")
    if out.suffix.lower() != ".png":
        raise InputError(f"expected a .png output path, got '{out}'", key="-o")
    import matplotlib

    matplotlib.use("Agg")
    from sitframe.sim.draw import plot_world

    fig = plot_world(world)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=150, bbox_inches="tight")
    except OSError as exc:
        raise InputError(f"cannot write the picture: {exc.strerror or exc}", file=str(out),
                         key="-o") from None
    print(out)
    return 0


def cmd_presets() -> int:
    from sitframe.contract.config import list_presets, load_config

    for name in list_presets():
        cfg, _s, _b = load_config(name)
        print(f"{name:24} {cfg['experiment']['description']}")
    return 0


def cmd_plugins(args: argparse.Namespace) -> int:
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager
    from sitframe.contract.tables import plugin_tables, tables_reference

    pm = get_plugin_manager(plugins_dirs=args.plugins_dir)
    reg = Registry.collect(pm, strict=False)  # list everything, clashes marked
    tables = plugin_tables(reg, strict=False)
    if args.tables:
        print(tables_reference(tables, reg))
        return 0
    for info, comps in reg.plugins_table():
        print(info.describe())
        for kind, names in comps.items():
            print(f"    {kind:12} {', '.join(names)}")
        own = sorted({t for t, owners in tables.owners.items()
                      for _k, _n, plugin in owners if plugin == info.name})
        if own:
            print(f"    {'table':12} {', '.join(f'[{t}]' for t in own)}")
        if not comps:
            print("    (observer hooks only)")
    for msg in [*getattr(pm, "sitframe_clashes", []), *reg.clashes, *tables.clashes]:
        print(f"CLASH: {msg}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console_main())
