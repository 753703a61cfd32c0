"""Run trials in parallel: a local process pool or a Dask distributed cluster.

Every executor (:class:`SerialExecutor` in this process, :class:`ProcessExecutor`,
:class:`DaskExecutor`) has the same small protocol: ``submit(fn, *args)`` a task,
``wait_first(futures)``, ``cancel(futures)``, ``capacity`` and ``shutdown``.
:class:`TrialPipeline` feeds trials to any of them and :class:`InOrder` releases
finished trials in trial order; the run driver (:func:`sitframe.runs.experiment.drive`)
composes the two for ``run``, ``run --resume`` and ``sweep`` alike. Workers only
compute: each rebuilds the components from the config and the plugin folders
(cached per worker, keyed by the config's hash) and returns the trial's arrays;
the calling process hands them to the observers, so exactly one process writes
the HDF5 log, in trial order.

Why one module of this size: the three executors share one protocol and one retry and
release logic (a Dask task lost with its worker is the pool's lost process); apart, each
would repeat it.

Results are bit-identical to a serial run: a trial depends only on its
:class:`~sitframe.runs.loop.TrialSpec` (its seed is spawned from the run seed
and its index) and on the config, never on which worker runs it or when; across
machines only for the same arithmetic (:mod:`sitframe.runs.arithmetic`), which a
Dask cluster checks on every worker.

``sitframe_step`` observers fire only in-process (:class:`SerialExecutor`,
``--workers 1``); with a pool they do not see iterations, and progress
advances per finished trial.

Start method: worker processes come from a ``forkserver`` (``spawn`` where
there is none), not from ``fork``. Forking the main process is unsafe here:
it may hold HDF5 library state mid-write (h5py is not fork-safe) and
runs threads (a rich progress bar, a Dask client) whose locks a forked child
would inherit held. The forkserver preloads sitframe once, so a worker
starts in milliseconds, and the pool is warmed up while the main process
collects and clusters.

Ctrl-C: workers ignore SIGINT (a terminal sends it to the whole process
group); the main process cancels pending trials, asks running workers to
stop (SIGTERM, which a worker turns into :class:`TaskCancelled` inside the
task, so it never dies half-way through sending a result, which would leave
the pool's result pipe holding a partial message and the main process
hanging at exit), waits for the workers to exit and re-raises, so the run is
marked ``aborted`` with finished trials kept.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import os
import re
import signal
import threading
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import suppress
from typing import TYPE_CHECKING, Any

from sitframe import scratch
from sitframe.errors import (
    InputError,
    PluginFault,
    TaskCancelled,
    quiet_teardown,
    show_warning,
    warn,
)
from sitframe.logs.interrupts import deferred_interrupt
from sitframe.params import environment
from sitframe.runs.arithmetic import arithmetic, check_same_arithmetic
from sitframe.sim import kernels

if TYPE_CHECKING:
    from sitframe.contract.records import TrialResult
    from sitframe.runs.loop import TrialSpec

#: Seconds to wait for a Dask scheduler before giving up.
DASK_CONNECT_TIMEOUT = 5.0


# ---------------------------------------------------------------------------
# Worker side
# ---------------------------------------------------------------------------


#: Worker-side state: whether a task is running, and whether the run was cancelled.
_worker_state = {"in_task": False, "cancelled": False}


def _run_task(fn: Callable[..., Any], *args: Any) -> Any:
    """Worker side of every :meth:`ProcessExecutor.submit`: run ``fn`` as a cancellable task."""
    if _worker_state["cancelled"]:
        raise TaskCancelled("the run was cancelled")
    _worker_state["in_task"] = True
    try:
        return fn(*args)
    finally:
        _worker_state["in_task"] = False


def _on_sigterm(_signum: int, _frame: Any) -> None:
    """SIGTERM in a worker: stop the task in progress (never the pool's own I/O)."""
    _worker_state["cancelled"] = True
    if _worker_state["in_task"]:
        raise TaskCancelled("the run was cancelled")


def _worker_init(lifeline: Any = None, inherited_writer: Any = None,
                 said: Any = None) -> None:
    """Pool worker set-up: ignore SIGINT, exit when the main process is gone.

    Ctrl-C in a terminal reaches the whole process group; only the main
    process decides what to do about it. ``lifeline`` is the read end of a
    pipe whose only write end the main process holds: when the main process
    dies (even by SIGKILL) the read sees EOF and the worker exits, instead
    of lingering blocked on the task queue (whose pipe the workers
    themselves keep open). A long trial's arrays in scratch files are handed back by the
    files' names (:func:`sitframe.scratch.share_by_name`); ``said``, the pool's flag that a
    scratch file could not be made, keeps that warning to one line for the whole pool.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    scratch.share_by_name()  # (a long trial reaches the main process as its files' names)
    if said is not None:
        scratch.share_warning(said)
    warnings.showwarning = show_warning  # (a worker writes to the command's stderr)
    quiet_teardown()
    if inherited_writer is not None:
        inherited_writer.close()
    if lifeline is None:
        return

    def watch() -> None:
        try:
            while True:
                lifeline.recv_bytes()
        except (EOFError, OSError):
            pass
        os._exit(1)

    threading.Thread(target=watch, name="sitframe-lifeline", daemon=True).start()


# ---------------------------------------------------------------------------
# Executors
# ---------------------------------------------------------------------------


class PoolExecutor:
    """The executor protocol: tasks submitted, waited for and cancelled.

    Subclasses provide :meth:`submit`, :meth:`wait_first`, :meth:`cancel`,
    :attr:`capacity` and :meth:`shutdown`. ``in_process`` executors run tasks
    in the calling process, on the caller's own experiment (so
    ``sitframe_step`` observers fire); the others receive a picklable
    :class:`~sitframe.runs.experiment.Setup` and rebuild the experiment.
    """

    #: Tasks run in this process (and ``sitframe_step`` observers fire).
    in_process = False
    #: Tasks the workers can run at once.
    capacity: int = 1

    def submit(self, fn: Callable[..., Any], *args: Any) -> Any:  # pragma: no cover
        raise NotImplementedError

    def wait_first(self, futures: Iterable[Any]) -> set[Any]:  # pragma: no cover
        """Block until at least one of ``futures`` is done; return the done ones."""
        raise NotImplementedError

    def cancel(self, futures: Iterable[Any]) -> None:  # pragma: no cover
        raise NotImplementedError

    def warm(self, fn: Callable[[Any], Any], arg: Any) -> None:
        """Called before the collect stage: a chance to start the workers (``fn(arg)`` each)."""

    @property
    def task_map(self) -> _TaskMap:
        """This pool as a :class:`~sitframe.situations.clustering.TaskMap` (for the clustering
        stage)."""
        return _TaskMap(self)

    def shutdown(self, cancel: bool = False) -> None:
        """Release the workers (``cancel=True``: drop queued and stop running work)."""

    def __enter__(self) -> PoolExecutor:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        self.shutdown(cancel=exc_type is not None)


class _TaskMap:
    """``pmap(fn, tasks)``: ``fn(*args)`` for each of ``tasks`` on the pool, results in order."""

    def __init__(self, executor: PoolExecutor) -> None:
        self.executor = executor

    @property
    def capacity(self) -> int:
        return self.executor.capacity

    def __call__(self, fn: Callable[..., Any], tasks: Sequence[tuple[Any, ...]]) -> list[Any]:
        futures = [self.executor.submit(fn, *args) for args in tasks]
        try:
            return [f.result() for f in futures]
        except BaseException:
            self.executor.cancel([f for f in futures if not f.done()])
            raise


class InOrder:
    """Releases results in a given order of keys, each once it and all before it arrived.

    The one place where finished trials are put back in trial order (the log
    is written in that order whatever order the workers finish in).
    """

    def __init__(self, order: Iterable[Any]) -> None:
        self.order = list(order)
        self._waiting: dict[Any, Any] = {}
        self.released = 0

    def add(self, key: Any, value: Any) -> list[Any]:
        """Record ``value`` for ``key``; return the values now released, in order."""
        self._waiting[key] = value
        out = []
        while self.released < len(self.order) and self.order[self.released] in self._waiting:
            out.append(self._waiting.pop(self.order[self.released]))
            self.released += 1
        return out

    @property
    def complete(self) -> bool:
        """Whether every key has been released."""
        return self.released == len(self.order)


def _earlier(tag: Any, other: Any) -> bool:
    """Whether task ``tag`` comes before ``other`` in release order (tags of one kind)."""
    try:
        return bool(tag < other)
    except TypeError:
        return False


class TrialPipeline:
    """Feeds trials to an executor and yields them as they complete.

    Each trial is split into its learning part and its
    evaluations (:func:`~sitframe.runs.loop.evaluation_specs`), which run as
    separate tasks once the learning part has finished: the work then comes
    in pieces small enough to keep every worker busy until the end, instead of
    one worker finishing the last whole trial alone. At most ``window``
    learning tasks are in flight; evaluations are submitted ahead of further
    learning tasks, so trials complete roughly in index order (and reach the
    log early). The evaluations are attached in world order, exactly as
    :func:`~sitframe.runs.loop.simulate` attaches them, so the assembled
    result is identical to a serial one.

    Parameters
    ----------
    executor
        Where the tasks run.
    run
        The task: ``run(handle, spec) -> TrialResult`` (module-level, so a
        pool can pickle it by reference).
    work
        How a trial splits into tasks and is put back together (the control loop's
        :data:`~sitframe.runs.loop.TRIAL_WORK`): ``learning(spec)`` the learning part's
        spec, ``evaluations(spec, result)`` the evaluations' specs once it finished,
        ``attach(result, world, evaluation)`` adds one to the trial's result.

    Notes
    -----
    Iterating yields ``("trial", tag, TrialResult)`` when a trial is complete
    and ``("call", tag, value)`` when a call added by :meth:`add_call` returns,
    in completion order. Use it as a context manager: leaving it early (an
    error, Ctrl-C) cancels every task still pending.
    """

    def __init__(self, executor: PoolExecutor, run: Callable[[Any, TrialSpec], TrialResult],
                 work: Any, window: int | None = None) -> None:
        self.executor = executor
        self.run = run
        self.work = work
        self.window = window or executor.capacity + (0 if executor.in_process else 1)
        self._queue: deque[tuple[Any, Any, TrialSpec]] = deque()
        self._inflight: dict[Any, tuple[str, Any, Any]] = {}
        self._partial: dict[Any, list[Any]] = {}
        self._learning = 0

    def add_trials(self, items: Iterable[tuple[Any, Any, TrialSpec]]) -> None:
        """Queue trials as ``(tag, handle, spec)``; they start as the window allows."""
        self._queue.extend(items)

    def add_call(self, tag: Any, fn: Callable[..., Any], *args: Any) -> None:
        """Submit ``fn(*args)`` now (ahead of queued trials)."""
        self._inflight[self.executor.submit(fn, *args)] = ("call", tag, None)

    def _fill(self) -> None:
        while self._queue and self._learning < self.window:
            tag, handle, spec = self._queue.popleft()
            fut = self.executor.submit(self.run, handle, self.work.learning(spec))
            self._inflight[fut] = ("learn", tag, (handle, spec))
            self._learning += 1

    def _fault(self, failure: tuple[Any, PluginFault] | None, kind: str, tag: Any,
               exc: PluginFault) -> tuple[Any, PluginFault]:
        """Plugin code failed in task ``tag``. Trials before it still finish and reach the
        log (as in a serial run); nothing after it starts, what is running is dropped."""
        if kind == "learn":
            self._learning -= 1
        if failure is None or _earlier(tag, failure[0]):
            failure = (tag, exc)
        self._queue = deque(q for q in self._queue if _earlier(q[0], failure[0]))
        return failure

    def _done(self, kind: str, tag: Any, info: Any, value: Any) -> TrialResult | None:
        """A finished task's trial when it is complete (else its evaluations are submitted)."""
        if kind == "learn":
            self._learning -= 1
            handle, spec = info
            evs = self.work.evaluations(spec, value)
            if not evs:
                return value
            self._partial[tag] = [value, [None] * len(evs), len(evs), [ev.world for ev in evs]]
            for i, ev in enumerate(evs):
                self._inflight[self.executor.submit(self.run, handle, ev)] = ("eval", tag, i)
            return None
        entry = self._partial[tag]
        entry[1][info] = value
        entry[2] -= 1
        if entry[2]:
            return None
        result, done, _n, worlds = self._partial.pop(tag)
        for world, ev_result in zip(worlds, done, strict=True):
            self.work.attach(result, world, ev_result)
        return result

    def __iter__(self) -> Iterator[tuple[str, Any, Any]]:
        failure: tuple[Any, PluginFault] | None = None  # (tag, fault) of the earliest fault
        while True:
            self._fill()
            if not self._inflight:
                if failure is not None:
                    raise failure[1]
                return
            for fut in self.executor.wait_first(list(self._inflight)):
                kind, tag, info = self._inflight.pop(fut)
                try:
                    value = fut.result()  # re-raises a worker's exception here
                except PluginFault as exc:
                    failure = self._fault(failure, kind, tag, exc)
                    continue
                except InputError as exc:  # (say whose: the run driver locates it)
                    exc.task = tag
                    raise
                if failure is not None and not _earlier(tag, failure[0]):
                    if kind == "learn":
                        self._learning -= 1
                    continue
                if kind == "call":
                    yield "call", tag, value
                elif (trial := self._done(kind, tag, info, value)) is not None:
                    yield "trial", tag, trial

    def cancel(self) -> None:
        """Drop queued trials and cancel every task in flight."""
        self._queue.clear()
        if self._inflight:
            self.executor.cancel(list(self._inflight))
        self._inflight.clear()

    def __enter__(self) -> TrialPipeline:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if self._inflight or self._queue:
            self.cancel()


class _Deferred(cf.Future):  # type: ignore[type-arg]
    """A task of :class:`SerialExecutor`: run when waited for, in this process."""

    def __init__(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
        super().__init__()
        self._call: tuple[Callable[..., Any], tuple[Any, ...]] | None = (fn, args)

    def run(self) -> None:
        if self._call is None:
            return
        (fn, args), self._call = self._call, None
        try:
            self.set_result(fn(*args))
        except Exception as exc:  # noqa: BLE001 - delivered through the future, like a pool
            self.set_exception(exc)

    def result(self, timeout: float | None = None) -> Any:
        self.run()
        return super().result(timeout)


class SerialExecutor(PoolExecutor):
    """Runs each task in this process, one at a time (``--workers 1``).

    A task runs when it is waited for, in the order submitted, on the
    caller's own experiment: ``sitframe_step`` observers fire, and a trial
    reaches the observers before the next one starts.
    """

    in_process = True
    capacity = 1

    def submit(self, fn: Callable[..., Any], *args: Any) -> cf.Future[Any]:
        return _Deferred(fn, args)

    def wait_first(self, futures: Iterable[Any]) -> set[Any]:
        futures = list(futures)
        pending = [f for f in futures if not f.done()]
        if pending and len(pending) == len(futures):
            pending[0].run()
        return {f for f in futures if f.done()}

    def cancel(self, futures: Iterable[Any]) -> None:
        for f in futures:
            f.cancel()


def start_method() -> str:
    """The multiprocessing start method of the pool (env ``SITFRAME_START_METHOD`` overrides)."""
    methods = mp.get_all_start_methods()
    wanted = environment("SITFRAME_START_METHOD")
    if wanted:
        if wanted not in methods:
            raise InputError(f"unknown start method '{wanted}'; this platform has "
                             f"{', '.join(methods)}", key="SITFRAME_START_METHOD")
        return wanted
    return "forkserver" if "forkserver" in methods else "spawn"


def _mp_context(method: str) -> mp.context.BaseContext:
    ctx = mp.get_context(method)
    if method == "forkserver":  # (workers fork from it with the compiled kernels loaded)
        compiled = ["sitframe.sim.numba_cache", "sitframe.sim.kernels_numba"]  # (in this order)
        ctx.set_forkserver_preload(["sitframe.runs.parallel", "sitframe.runs.experiment",
                                    "sitframe.runs.loop", *(compiled if kernels.wanted() else [])])
    return ctx


class ProcessExecutor(PoolExecutor):
    """Trials in a local pool of ``workers`` processes (``--workers K``).

    Parameters
    ----------
    workers
        Number of worker processes (at least 1; 1 still uses a subprocess,
        the CLI uses :class:`SerialExecutor` for 1).
    """

    def __init__(self, workers: int) -> None:
        if workers < 1:
            raise InputError(f"must be at least 1, got {workers}", key="--workers")
        self.workers = int(workers)
        self._pool: cf.ProcessPoolExecutor | None = None
        self._lifeline: tuple[Any, Any] | None = None

    @property
    def pool(self) -> cf.ProcessPoolExecutor:
        if self._pool is None:
            method = start_method()
            ctx = _mp_context(method)
            reader, writer = ctx.Pipe(duplex=False)
            self._lifeline = (reader, writer)  # never written; closed when we exit
            # A forked child inherits the write end too and must close it.
            said = ctx.Event()  # (the scratch folder's warning: once for the whole pool)
            scratch.share_warning(said)
            initargs = (reader, writer if method == "fork" else None, said)
            self._pool = cf.ProcessPoolExecutor(self.workers, mp_context=ctx,
                                                initializer=_worker_init, initargs=initargs)
        return self._pool

    def warm(self, fn: Callable[[Any], Any], arg: Any) -> None:
        for _ in range(self.workers):  # one submit per worker starts them all now
            self.submit(fn, arg)

    @property
    def capacity(self) -> int:  # type: ignore[override]
        return self.workers

    def submit(self, fn: Callable[..., Any], *args: Any) -> cf.Future[Any]:
        # A submit may start a worker process; a Ctrl-C in the middle would leave
        # a started process the pool does not know of (it then fails noisily
        # once the main process is gone), so the interrupt waits until it returns.
        with deferred_interrupt():
            return self.pool.submit(_run_task, fn, *args)

    def wait_first(self, futures: Iterable[Any]) -> set[Any]:
        return cf.wait(list(futures), return_when=cf.FIRST_COMPLETED).done

    def cancel(self, futures: Iterable[Any]) -> None:
        futures = list(futures)
        for f in futures:
            f.cancel()
        if any(f.running() for f in futures):
            self.shutdown(cancel=True)

    def shutdown(self, cancel: bool = False) -> None:
        pool, self._pool = self._pool, None
        lifeline, self._lifeline = self._lifeline, None
        if pool is None:
            return
        if cancel:
            # A running task cannot be cancelled through its future: SIGTERM makes
            # the worker raise TaskCancelled inside it (and fail any later task at
            # once); the workers then leave through the pool's normal shutdown.
            for p in list(getattr(pool, "_processes", {}).values()):
                if p.is_alive():
                    p.terminate()
        pool.shutdown(wait=True, cancel_futures=cancel)
        if lifeline is not None:
            for conn in lifeline:
                conn.close()


class DaskExecutor(PoolExecutor):
    """Trials on an existing Dask distributed cluster (``--scheduler ADDRESS``).

    Every worker needs sitframe (and any third-party plugin packages)
    installed; loose ``--plugins-dir`` folders must exist at the same path on
    the workers. The workers connected when sitframe connects must compute
    with this process's :func:`arithmetic` (else :class:`InputError`, naming
    the setting that makes them match), and every task checks its worker's
    again before it runs (a worker that joined later), failing the run with
    the same message rather than returning a trial of another arithmetic.

    Parameters
    ----------
    address
        The scheduler's address, e.g. ``tcp://10.0.0.5:8786``.
    timeout
        Seconds to wait for the connection before raising :class:`InputError`
        (default :data:`DASK_CONNECT_TIMEOUT`, read when called).
    """

    def __init__(self, address: str, timeout: float | None = None) -> None:
        timeout = DASK_CONNECT_TIMEOUT if timeout is None else timeout
        try:
            from distributed import Client
        except ImportError:
            raise InputError("--scheduler needs Dask distributed, which is not installed "
                             "(pip install 'sitframe[dask]')", key="--scheduler") from None
        self.address = address
        scheme = _check_address(address)
        try:
            self.client = _connect(Client, address, timeout)
        except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, ValueError (bad address)
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise InputError(f"cannot reach the Dask scheduler at '{address}' within "
                             f"{timeout:g} s ({msg})", key="--scheduler") from None
        self.arithmetic = arithmetic()
        try:
            # (a worker that leaves while asked, e.g. killed under churn, is skipped: every
            # task checks its worker's arithmetic again before it returns a trial)
            check_same_arithmetic(self.arithmetic,
                                  self.client.run(arithmetic, on_error="ignore"))
        except InputError:
            self.shutdown()
            raise
        if scheme not in ("tls", "wss", "inproc"):
            warn(f"--scheduler {address}: plain {scheme}; Dask unpickles what it receives, so "
                 "whoever can reach the scheduler can run code here and on the workers: use "
                 "tls:// on a shared network (see docs/how-to/dask.md)")

    @property
    def capacity(self) -> int:  # type: ignore[override]
        try:
            return max(1, sum(self.client.nthreads().values()))
        except Exception:  # noqa: BLE001 - a scheduler that cannot tell: assume one slot
            return 1

    def submit(self, fn: Callable[..., Any], *args: Any) -> _DaskTask:
        return _DaskTask(self, fn, args)

    def _remote(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> Any:
        return self.client.submit(_same_arithmetic_task, self.arithmetic, fn, *args, pure=False)

    def wait_first(self, futures: Iterable[Any]) -> set[Any]:
        from distributed import as_completed

        futures = list(futures)
        while not any(f.done() for f in futures):
            remote = {f.remote: f for f in futures}
            first = next(iter(as_completed(list(remote), loop=self.client.loop)))  # (our client)
            self._settle([remote[first], *(f for f in futures if f.remote.done())])
        return {f for f in futures if f.done()}

    def _settle(self, tasks: list[_DaskTask]) -> None:
        """Fetch the results of the finished ``tasks`` now, in one transfer, and release their
        copies on the workers: a worker killed later then loses no finished work (the
        scheduler would run every finished task it held again). A task lost with its worker
        more often than the scheduler retries (``KilledWorker``) is submitted again, up to
        :data:`DASK_RESUBMITS` times."""
        from distributed import KilledWorker

        tasks = [t for t in dict.fromkeys(tasks) if not t.done() and t.remote.done()]
        ok = {i: t.remote for i, t in enumerate(tasks) if t.remote.status == "finished"}
        for i, value in (self.client.gather(ok, errors="skip") if ok else {}).items():
            tasks[i].remote.release()  # (one lost since is computed again; gathered later)
            tasks[i].set_result(value)
        for t in tasks:
            if t.done() or t.remote.status == "cancelled":
                continue
            exc = t.remote.exception()
            if isinstance(exc, KilledWorker) and t.lost < DASK_RESUBMITS:
                t.lost += 1
                t.remote.release()
                t.remote = self._remote(t.fn, t.args)
                continue
            if isinstance(exc, KilledWorker):
                exc = InputError(f"a task was lost with its Dask worker {t.lost + 1} times over "
                                 f"(the workers of '{self.address}' keep dying); the finished "
                                 "trials are in the log: finish it with `sitframe run --resume "
                                 "LOG` (or the sweep with --reuse)", key="--scheduler")
            t.remote.release()
            t.set_exception(exc)

    def cancel(self, futures: Iterable[Any]) -> None:
        futures = list(futures)
        self.client.cancel([f.remote for f in futures])
        for f in futures:
            f.cancel()

    def shutdown(self, cancel: bool = False) -> None:
        client, self.client = self.client, None
        if client is not None:
            client.close()


#: Times a task lost with its worker more often than the scheduler retries is submitted again.
DASK_RESUBMITS = 5


class _DaskTask(cf.Future):  # type: ignore[type-arg]
    """A task on the Dask cluster, seen as a local future: its result is fetched once the
    task is done (:meth:`DaskExecutor._settle`) and kept here, not on a worker."""

    def __init__(self, executor: DaskExecutor, fn: Callable[..., Any],
                 args: tuple[Any, ...]) -> None:
        super().__init__()
        self.executor, self.fn, self.args, self.lost = executor, fn, args, 0
        self.remote = executor._remote(fn, args)

    def result(self, timeout: float | None = None) -> Any:
        while not self.done():
            self.executor.wait_first([self])
        return super().result(timeout)


def _same_arithmetic_task(expected: str, fn: Callable[..., Any], *args: Any) -> Any:
    """A Dask task: ``fn(*args)`` on a worker whose :func:`arithmetic` is ``expected``."""
    try:
        from distributed import get_worker

        name = str(get_worker().address)
    except (ImportError, ValueError):  # (not on a Dask worker)
        name = f"pid {os.getpid()}"
    check_same_arithmetic(expected, {name: arithmetic()})
    return fn(*args)


def _connect(client_class: Any, address: str, timeout: float) -> Any:
    """``client_class(address, ...)``; a client that fails half-way is closed at once, quietly.

    Left to the garbage collector, such a client tries to close itself when the error
    that holds it is dropped, waits twice the connect timeout for a scheduler it never
    reached and prints a ``TimeoutError`` traceback, seconds after sitframe's one line.
    """
    made: list[Any] = []

    class _Client(client_class):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            made.append(self)
            super().__init__(*args, **kwargs)

    try:
        return _Client(address, timeout=timeout, set_as_default=False)
    except BaseException:
        for client in made:
            with suppress(Exception):
                client.status = "closed"  # (its __del__ then does nothing)
                client._loop_runner.stop()
        raise


def _check_address(address: str) -> str:
    """The scheme of a Dask address, or an InputError for a malformed one (checked before a
    Client exists: a Client that fails half-way prints a traceback when collected). A host
    and a port are required (a Client does not default the port), and ``tls://`` or
    ``wss://`` needs the client's certificates in the Dask configuration."""
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import backends

    try:
        if not address.strip():
            raise ValueError("it is empty")
        scheme, loc = parse_address(address)
        if scheme not in backends:
            raise ValueError(f"unknown scheme '{scheme}'; known: {', '.join(sorted(backends))}")
        if scheme in ("tcp", "tls", "ws", "wss"):
            if not re.search(r":\d+$", loc):
                raise ValueError("no port number")
            host, port = parse_host_port(loc)
            if not host:
                raise ValueError("no host")
            if not 0 < int(port) < 65536:
                raise ValueError(f"port {port} out of range 1-65535")
    except (ValueError, TypeError) as exc:
        raise InputError(f"malformed Dask scheduler address '{address}' ({exc}); expected e.g. "
                         "tls://host:8786", key="--scheduler") from None
    if scheme in ("tls", "wss"):
        from distributed.security import Security

        if Security().get_connection_args("client").get("ssl_context") is None:
            raise InputError(f"'{address}' is a {scheme}:// address, but the Dask configuration "
                             "gives this client no TLS certificates; expected "
                             "distributed.comm.tls.ca-file, .client.cert and .client.key set "
                             "(e.g. DASK_DISTRIBUTED__COMM__TLS__CA_FILE=...), or a tcp:// "
                             "address", key="--scheduler")
    return str(scheme)


def make_executor(workers: int | None = None, scheduler: str | None = None,
                  n_tasks: int | None = None) -> PoolExecutor:
    """The executor the CLI options ask for.

    Parameters
    ----------
    workers
        ``--workers``: processes in the local pool; ``None`` = ``os.cpu_count()``.
        1 (or only one task to run) = in-process serial execution.
    scheduler
        ``--scheduler``: a Dask scheduler address (``workers`` must be ``None``).
    n_tasks
        How many trials will run (no more workers than that are started).
    """
    if scheduler is not None:
        if workers is not None:
            raise InputError("give either --workers (local processes) or --scheduler "
                             "(a Dask cluster), not both", key="--workers")
        return DaskExecutor(scheduler)
    if workers is not None and workers < 1:
        raise InputError(f"must be at least 1, got {workers}", key="--workers")
    k = workers if workers is not None else (os.cpu_count() or 1)
    if n_tasks is not None:
        k = min(k, max(n_tasks, 1))
    if k <= 1:
        return SerialExecutor()
    return ProcessExecutor(k)


__all__ = ["DaskExecutor", "InOrder", "PoolExecutor", "ProcessExecutor", "SerialExecutor",
           "TaskCancelled", "TrialPipeline", "make_executor"]
