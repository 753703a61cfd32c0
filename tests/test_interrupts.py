"""Ctrl-C during an HDF5 transaction waits for the transaction to finish."""

from __future__ import annotations

import os
import signal
import sys
import time

import pytest

from sitframe.contract.records import RunInfo
from sitframe.logs.interrupts import (
    Terminated,
    deferred_interrupt,
    terminate_as_interrupt,
)
from sitframe.logs.reader import open_log
from sitframe.logs.writer import LogWriter


@pytest.fixture
def default_sigint():
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def test_sigint_inside_block_is_raised_when_the_block_ends(default_sigint):
    reached_end = False
    with pytest.raises(KeyboardInterrupt):
        with deferred_interrupt():
            os.kill(os.getpid(), signal.SIGINT)
            reached_end = True
    assert reached_end
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_no_signal_no_exception_and_handler_restored(default_sigint):
    with deferred_interrupt(), deferred_interrupt():
        pass
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_custom_handler_is_left_alone():
    seen = []
    old = signal.signal(signal.SIGINT, lambda s, f: seen.append(s))
    try:
        with deferred_interrupt():
            os.kill(os.getpid(), signal.SIGINT)
        assert seen == [signal.SIGINT]
    finally:
        signal.signal(signal.SIGINT, old)


def test_sigint_during_a_log_transaction_leaves_the_transaction_complete(default_sigint, tmp_path):
    path = tmp_path / "run.h5"
    w = LogWriter(path)
    w.start(RunInfo(name="x", config={}, config_text="", config_hash="", seed=1, out=str(path),
                    n_trials=1, iterations=1))
    with pytest.raises(KeyboardInterrupt):
        with w._open() as f:
            os.kill(os.getpid(), signal.SIGINT)
            f.attrs["status"] = "aborted"  # runs: the interrupt is held back
    assert open_log(path).status == "aborted"
    assert not w.part.exists()


class _RaisesWhenCollected:
    """Stands for a finaliser that a signal interrupted: it raises the signal's exception
    where Python can only print it and go on."""

    def __init__(self, exc: type[BaseException]) -> None:
        self.exc = exc

    def __del__(self) -> None:
        raise self.exc


@pytest.mark.parametrize("exc", [Terminated, KeyboardInterrupt])
def test_an_interrupt_swallowed_by_a_finaliser_is_delivered_again(default_sigint, capsys, exc):
    """SIGTERM or Ctrl-C landing in a finaliser or weakref callback (a garbage collection)
    is not lost and prints no traceback: it is raised in the interrupted code after."""
    reached = False
    with pytest.raises(exc), terminate_as_interrupt():
        obj = _RaisesWhenCollected(exc)
        del obj  # Python calls sys.unraisablehook here instead of raising
        time.sleep(5)  # the signal comes again and ends the wait
        reached = True
    assert not reached
    assert "Exception ignored" not in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_other_unraisable_exceptions_go_to_the_hook_before(monkeypatch):
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", seen.append)
    with terminate_as_interrupt():
        obj = _RaisesWhenCollected(ValueError)
        del obj
    assert [type(u.exc_value) for u in seen] == [ValueError]
