"""Ctrl-C handling around HDF5 I/O.

A ``KeyboardInterrupt`` raised while h5py is inside one of its C callbacks
(attribute iteration, visiting items) does not propagate as itself: h5py
reports it as a ``SystemError`` ("returned a result with an exception
set"), so a Ctrl-C at the wrong moment would end ``sitframe run`` with a
traceback and exit status 1 instead of marking the log aborted and exiting
130. :func:`deferred_interrupt` holds SIGINT back for the length of one short
HDF5 transaction and re-raises it as ``KeyboardInterrupt`` when the block
ends, so every log transaction is atomic with respect to Ctrl-C too.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Defer SIGINT until the ``with`` block ends, then raise ``KeyboardInterrupt``.

    Only acts in the main thread and only when Python's default SIGINT
    handler is installed (a program that installed its own handler, or
    ignores SIGINT, keeps its choice). Nested uses are free: the inner block
    sees the deferring handler and leaves it alone.
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    received: list[int] = []

    def hold(signum: int, _frame: object) -> None:
        received.append(signum)

    signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if received:
            raise KeyboardInterrupt


__all__ = ["deferred_interrupt"]
