"""Ctrl-C and SIGTERM handling around HDF5 I/O.

A ``KeyboardInterrupt`` raised while h5py is inside one of its C callbacks
(attribute iteration, visiting items) does not propagate as itself: h5py
reports it as a ``SystemError`` ("returned a result with an exception
set"), so a Ctrl-C at the wrong moment would end ``sitframe run`` with a
traceback and exit status 1 instead of marking the log aborted and exiting
130. :func:`deferred_interrupt` holds SIGINT back for the length of one short
HDF5 transaction and re-raises it as ``KeyboardInterrupt`` when the block
ends, so every log transaction is atomic with respect to Ctrl-C too.

SIGTERM (``kill PID``, a batch system's time limit) is treated like Ctrl-C
once :func:`terminate_as_interrupt` is installed (the CLI does): it raises
:class:`Terminated`, a ``KeyboardInterrupt``, so the run is marked
``aborted`` the same way, and it is deferred around transactions the same
way; the CLI then exits with status 143 (128 + SIGTERM) instead of 130.

A signal that arrives while Python runs a finaliser or a weakref callback (a garbage
collection, at any moment) would raise there, where Python cannot propagate it: it prints
"Exception ignored in ..." with a traceback and goes on, and the interrupt would be lost.
Within :func:`terminate_as_interrupt` such a swallowed :class:`Terminated` or
``KeyboardInterrupt`` is delivered again (:func:`redeliver`): the signal is raised anew and
its handler runs in the interrupted code once the callback has returned (should it land in
a callback again, it is delivered again).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C (so everything that handles Ctrl-C handles it)."""


def raise_terminated(_signum: int, _frame: Any) -> None:
    """SIGTERM handler: raise :class:`Terminated` in the main thread."""
    raise Terminated


#: Set while :func:`redeliver` runs: a signal handled then would raise inside the hook and
#: be lost, so the sender waits until it is clear.
_IN_HOOK = threading.Event()
#: How long [s] the sender waits after the hook returned (the main thread finishes the
#: callback's bookkeeping in that time even on a loaded machine).
REDELIVER_AFTER = 0.05


def _send_when_clear(sig: int) -> None:
    """Send ``sig`` to this process once :func:`redeliver` has returned, and a moment more."""
    while _IN_HOOK.is_set():
        time.sleep(0.001)
    time.sleep(REDELIVER_AFTER)
    os.kill(os.getpid(), sig)


def redeliver(unraisable: Any, previous: Any = sys.__unraisablehook__) -> None:
    """``sys.unraisablehook``: an interrupt swallowed in a finaliser or weakref callback is
    raised again as its signal (SIGTERM for :class:`Terminated`, SIGINT for any other
    ``KeyboardInterrupt``); anything else goes to ``previous``."""
    exc = unraisable.exc_value
    if not isinstance(exc, KeyboardInterrupt):
        previous(unraisable)
        return
    # (sent from another thread after this hook returned: a handler run while the hook
    # runs would raise inside it, still in the callback, and be lost; a fixed 1 ms delay
    # lost it on a loaded machine)
    sig = signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT
    _IN_HOOK.set()
    try:
        threading.Thread(target=_send_when_clear, args=(sig,), daemon=True).start()
    finally:
        _IN_HOOK.clear()


@contextmanager
def terminate_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (if SIGTERM has its default action),
    and an interrupt swallowed by a finaliser or weakref callback is delivered again.

    The previous handler and ``sys.unraisablehook`` are restored at the end. Only acts in
    the main thread.
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL):
        yield
        return
    signal.signal(signal.SIGTERM, raise_terminated)
    hook = sys.unraisablehook
    sys.unraisablehook = lambda u: redeliver(u, hook)
    try:
        yield
    finally:
        sys.unraisablehook = hook
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


@contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Defer SIGINT (and SIGTERM) until the ``with`` block ends, then raise.

    SIGINT is deferred only when Python's default SIGINT handler is
    installed (a program that installed its own handler, or ignores SIGINT,
    keeps its choice), SIGTERM only when :func:`raise_terminated` handles
    it. At the end of the block a held SIGTERM raises :class:`Terminated`, a
    held SIGINT ``KeyboardInterrupt``. Only acts in the main thread. Nested
    uses are free: the inner block sees the deferring handler and leaves it
    alone.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handlers = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: raise_terminated}
    ours = [s for s, h in handlers.items() if signal.getsignal(s) is h]
    if not ours:
        yield
        return
    received: list[int] = []

    def hold(signum: int, _frame: object) -> None:
        received.append(signum)

    for s in ours:
        signal.signal(s, hold)
    try:
        yield
    finally:
        for s in ours:
            signal.signal(s, handlers[s])
        if signal.SIGTERM in received:
            raise Terminated
        if received:
            raise KeyboardInterrupt


__all__ = ["Terminated", "deferred_interrupt", "raise_terminated", "terminate_as_interrupt"]
