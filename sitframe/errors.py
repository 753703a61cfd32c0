"""Errors that reach the user as one clear line.

Every error caused by input (a config, a world file, a log, a plugin) is an
:class:`InputError`. It is a :class:`ValueError`, so library callers may catch
the standard type, and it carries *where* the problem is (file and key path)
so the CLI can print one line and exit with status 2.
"""

from __future__ import annotations

import difflib
import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any


class SitframeError(Exception):
    """Base class of the errors sitframe raises on purpose."""


class InputError(SitframeError, ValueError):
    """Bad input: names the file, the key path, what was wrong and what was expected.

    Parameters
    ----------
    message
        What was wrong and what was expected, e.g. ``"expected a number, got 'abc'"``.
    file
        The file the problem is in, if any.
    key
        Dotted key path inside that file, e.g. ``"walls[2].points[0]"``.
    """

    def __init__(self, message: str, *, file: str | None = None, key: str | None = None):
        self.message = message
        self.file = None if file is None else str(file)
        self.key = key
        super().__init__(self.__str__())

    def __str__(self) -> str:
        where = ": ".join(_printable(p) for p in (self.file, self.key) if p)
        return one_line(f"{where}: {self.message}" if where else self.message)

    def at(self, *, file: str | None = None, key_prefix: str | None = None) -> InputError:
        """Return a copy located in ``file`` and/or below ``key_prefix``."""
        key = self.key
        if key_prefix:
            key = f"{key_prefix}.{key}" if key else key_prefix
        return type(self)(self.message, file=file or self.file, key=key)


class DiskFullError(InputError):
    """A log could not be written because its disk is full (or the user's quota is used up).

    The message names the folder, what is free there and what the log needs, and says
    what was kept. ``folder`` and ``free`` (bytes) are kept for callers that write several
    logs (a sweep) and say what all of them need.
    """

    def __init__(self, message: str, *, file: str | None = None, key: str | None = None,
                 folder: str = "", free: int = 0) -> None:
        super().__init__(message, file=file, key=key)
        self.folder, self.free = folder, free

    def at(self, *, file: str | None = None, key_prefix: str | None = None) -> InputError:
        moved = super().at(file=file, key_prefix=key_prefix)
        return DiskFullError(moved.message, file=moved.file, key=moved.key,
                             folder=self.folder, free=self.free)


class InputTypeError(InputError, TypeError):
    """An :class:`InputError` for a value of the wrong type: also a :class:`TypeError`,
    as numpy and scikit-learn style callers expect."""


class PluginError(SitframeError):
    """A plugin failed: names the plugin, its origin and the hook or component."""


class TaskCancelled(SitframeError):
    """Raised inside a worker's task when the main process cancels the run."""


#: What plugin code may raise that is reported as the plugin's fault: any Exception, and
#: SystemExit (a plugin calling ``sys.exit()`` would otherwise end sitframe without a word).
PLUGIN_ERRORS = (Exception, SystemExit)

#: Exit status of the CLI when plugin code failed during a run (2 is bad input).
PLUGIN_FAULT_EXIT = 3


class PluginFault(PluginError):
    """Plugin code raised, or returned a value that breaks the contract, during a run.

    The message is one line naming the plugin (distribution and version, or
    file), the component, the method, the trial and iteration, and what went
    wrong. The CLI prints it and exits with :data:`PLUGIN_FAULT_EXIT`; the
    run's log keeps every finished trial, with status ``failed`` and the
    message in its ``failure`` attribute.

    Parameters
    ----------
    message
        What went wrong (the exception's type and message, or the broken rule).
    where
        ``"plugin X (dist 1.0, entry point): behaviour 'fuzzy-q' [behaviours.avoid]"``.
    method
        The method that failed (``read``, ``propose``, ``__call__`` ...).
    trial, iteration
        Where in the run, if inside the loop.
    """

    def __init__(self, message: str, *, where: str, method: str, trial: int | None = None,
                 iteration: int | None = None) -> None:
        self.message, self.where, self.method = message, where, method
        self.trial, self.iteration = trial, iteration
        at = "" if trial is None else f" in trial {trial}" + (
            "" if iteration is None else f", iteration {iteration}")
        super().__init__(one_line(f"{where}: {method}(){at}: {message}"))

    def __reduce__(self) -> tuple[Any, ...]:  # picklable across worker processes
        return (_fault, (self.message, self.where, self.method, self.trial, self.iteration))


def _fault(message: str, where: str, method: str, trial: int | None,
           iteration: int | None) -> PluginFault:
    return PluginFault(message, where=where, method=method, trial=trial, iteration=iteration)


_SAID: set[str] = set()


def note(message: str) -> None:
    """One line on stderr saying what a command chose to do for the user (not an error).

    Each message is said once per command (a sweep whose twenty points make the
    same choice says it once, not twenty times); :func:`sitframe.cli.app.main` starts
    every command afresh with :func:`forget_notes`.
    """
    if message not in _SAID:
        _SAID.add(message)
        print(f"sitframe: note: {one_line(message)}", file=sys.stderr)


def warn(message: str) -> None:
    """One ``sitframe: warning:`` line on stderr: something the user should know about an
    accepted input (it names the source: file and key, option, log), escaped onto one line."""
    print(f"sitframe: warning: {one_line(message)}", file=sys.stderr)


def show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                 file: Any = None, line: str | None = None) -> None:
    """``warnings.showwarning`` of the command line and its worker processes: a Python
    warning that reaches the user (none should: an accepted input's edge cases are checked
    or said by a sitframe warning of their own) is one ``sitframe: warning:`` line naming the
    code that warned, not Python's two lines with the source code."""
    where = filename.replace("\\", "/").rsplit("/", 1)[-1]
    warn(f"{category.__name__} in {where}:{lineno}: {message}")


def quiet_teardown() -> None:
    """Install ``sys.unraisablehook`` so that an exception raised in a destructor while the
    interpreter shuts down is dropped instead of printed as a traceback (llvmlite's
    compiled-code handles, closed twice at exit, print ``Exception ignored in ...
    AttributeError``); while the program runs, such exceptions still reach the previous
    hook. A command's stderr then ends with its own lines (its one error line on failure)."""
    previous = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        where = str(getattr(unraisable.object, "__module__", ""))
        if sys.is_finalizing() or where.startswith("llvmlite"):
            return
        previous(unraisable)

    if getattr(previous, "__name__", "") != "quiet_hook":
        hook.__name__ = "quiet_hook"
        sys.unraisablehook = hook


def one_line(text: str) -> str:
    """``text`` with every character that is not printable escaped (a newline as ``\\n``, an
    escape sequence as ``\\x1b``): text from files (a log's status, a TOML string) reaches
    the terminal on one line and cannot move the cursor or change colours."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                   for c in text)


def forget_notes() -> None:
    """Let :func:`note` say again what it has said (at the start of a command)."""
    _SAID.clear()


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """Return ``" (did you mean 'x'?)"`` for the closest choice, or ``""``."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def _printable(s: str) -> str:
    """``s``, or its escaped form if it holds control or other unprintable characters
    (a TOML key or a file name may contain a newline)."""
    return s if s.isprintable() else s.encode("unicode_escape").decode("ascii")


def located(exc: InputError, file: str | None) -> InputError:
    """``exc`` located in ``file`` if it names a config key but no file: a setting a
    component finds wrong only as a run goes (e.g. the goal pairs' ``min_distance`` in a
    world too small), whose key is in that config or log. Errors naming a command-line
    option (``--scheduler``) or a file already are returned as they are."""
    if exc.file is None and exc.key and not exc.key.startswith("-") and file:
        return exc.at(file=file)
    return exc


@contextmanager
def located_in(file: str | None) -> Iterator[None]:
    """Re-raise an :class:`InputError` of the block :func:`located` in ``file``."""
    try:
        yield
    except InputError as exc:
        raise located(exc, file) from None
