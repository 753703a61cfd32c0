"""The sitframe plugin contract: every hook a plugin may implement.

A plugin is any module or object with functions decorated by
:data:`sitframe.hookimpl`. Plugins are discovered from setuptools entry points
in the group ``"sitframe"`` (the built-in plugins are declared there too, in
sitframe's own ``pyproject.toml``), from loose ``.py`` files in a
``--plugins-dir``, or registered directly on a plugin manager made by
:func:`sitframe.contract.pluginmanager.get_plugin_manager`.

There are two kinds of hook:

*Registration hooks* (``sitframe_sensors`` ... ``sitframe_protocols``) are called
once per run, when the run resolves its components. Each returns a list of
*component factories*: classes (or callables) with a unique string attribute
``name``, called with the keyword parameters of the component's config table.
Every implementation is called and the lists are merged; two factories with
the same ``name`` in one kind are an error that names both plugins. The
interfaces the created components must satisfy are in
:mod:`sitframe.contract.components`.

*Observer hooks* (``sitframe_run_start`` ... ``sitframe_run_end``) are called
by the run driver (:mod:`sitframe.runs.experiment`) as a run progresses. They return nothing (but
``sitframe_trial_data``); every implementation is called. The HDF5 logger and
the progress bar are plugins on these hooks. Observer hooks are called in the
process that writes the run (the main process), so an observer never sees a
partial trial from a worker. ``sitframe_step`` and ``sitframe_trial_data`` are
the exceptions: they fire in the process that *simulates* the trial -- the
main process with ``--workers 1``, else a worker process, which loads the
same entry-point and ``--plugins-dir`` plugins -- so an observer that
accumulates per-iteration data there hands it back through
``sitframe_trial_data`` and it reaches the log with the trial.

Any exception raised by plugin code during a run (a hook, or a component's
method) is reported as one line naming the plugin, the component or hook, the
method, the trial and the iteration (:class:`sitframe.errors.PluginFault`);
the CLI exits with status 3 and the log keeps every finished trial.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pluggy

if TYPE_CHECKING:
    from sitframe.contract.records import RunInfo, StepRecord, TrialResult

hookspec = pluggy.HookspecMarker("sitframe")


# --------------------------------------------------------------------------
# Registration hooks
# --------------------------------------------------------------------------


@hookspec
def sitframe_sensors() -> list[Any]:
    """Register sensor factories.

    Called once per run, when components are resolved. A sensor turns the
    world and the robot's pose into one reading (e.g. the 8 Pioneer sonar
    ranges); see :class:`sitframe.contract.components.Sensor`.

    :return: A list of factories, each with a unique ``name`` attribute,
        called as ``factory(**params)`` with the keys of the config's
        ``[sensor]`` table (except ``component``).

    All implementations are called; their lists are merged.
    """


@hookspec
def sitframe_interpreters() -> list[Any]:
    """Register situation-interpreter factories.

    Called once per run, when components are resolved. An interpreter is
    fitted on collected readings (the *cluster* stage) and then turns each live
    reading into memberships of ``c`` situations; see
    :class:`sitframe.contract.components.SituationInterpreter`. An *evolving*
    interpreter (``evolving = True``) changes its situations during learning
    trials and reports each change as a
    :class:`sitframe.situations.events.SituationEvent` that behaviours follow in
    ``situations_changed(event)`` (the contract: :mod:`sitframe.situations`).

    **Situation spaces.** The same factories make the interpreter of every
    *situation space of its own*: a ``[spaces.NAME]`` table (its ``component``
    and parameters, plus the reserved keys ``view``, ``clusters_from`` and
    ``collect``) is a second interpreter that sees only the readings of its
    ``view``, is fitted on data of its own (or takes the situations of a log),
    and serves the behaviours (and the arbiter) whose tables say ``space =
    "NAME"``; the ``[interpreter]`` is the space ``"default"``. A behaviour or
    arbiter *reads* its space with no code of its own: ``bind(run)`` gets
    ``run.space`` and that space's ``run.n_situations``, ``reset`` its number
    of situations, and each :class:`sitframe.contract.records.Context` it is
    handed carries that space's ``memberships`` (and every space's in
    ``Context.spaces``). An evolving interpreter can only be the default space.

    :return: A list of factories with unique ``name`` attributes, called with
        the keys of the config's ``[interpreter]`` table (or of a
        ``[spaces.NAME]`` table, but its reserved keys).

    All implementations are called; their lists are merged.
    """


@hookspec
def sitframe_rewards() -> list[Any]:
    """Register reward factories.

    Called once per run, when components are resolved. A reward maps one
    :class:`sitframe.contract.records.Transition` to a float; a learning behaviour
    names the reward it learns from in its config table (``reward = "..."``);
    see :class:`sitframe.contract.components.Reward`.

    :return: A list of factories with unique ``name`` attributes, called with
        the keys of the behaviour's ``[behaviours.NAME.reward_params]`` table.

    All implementations are called; their lists are merged.
    """


@hookspec
def sitframe_behaviours() -> list[Any]:
    """Register behaviour factories.

    Called once per run, when components are resolved. A behaviour proposes a
    heading change (and optionally a speed) every iteration and may learn from
    its reward; see :class:`sitframe.contract.components.Behaviour`.

    :return: A list of factories with unique ``name`` attributes, called with
        the keys of a ``[behaviours.LABEL]`` table (except ``component``,
        ``reward`` and ``reward_params``).

    All implementations are called; their lists are merged.
    """


@hookspec
def sitframe_arbiters() -> list[Any]:
    """Register arbiter factories.

    Called once per run, when components are resolved. An arbiter fuses the
    behaviours' proposals into the one command the robot executes (a single
    behaviour, priority switching, context-dependent blending ...); see
    :class:`sitframe.contract.components.Arbiter`.

    :return: A list of factories with unique ``name`` attributes, called with
        the keys of the config's ``[arbiter]`` table.

    All implementations are called; their lists are merged.
    """


@hookspec
def sitframe_protocols() -> list[Any]:
    """Register evaluation-protocol factories.

    Called once per run, when components are resolved. A protocol says how the
    evaluate stage scores a run's behaviours in episodes: where each episode
    starts (and its goal), when it ends early (Gymnasium's *terminated*; the
    iteration limit is *truncation*) and how finished episodes are scored; see
    :class:`sitframe.contract.components.EvaluationProtocol`. A run uses the protocol
    that one of its components names in a class attribute
    ``evaluation_protocol`` (the built-in ``goal`` behaviour names
    ``"goal-episodes"``); without one, the built-in ``frozen``: one run from
    the start of each ``[evaluate] worlds`` world.

    :return: A list of factories with unique ``name`` attributes. A protocol's
        parameters are the keys of its config table (except ``worlds``, the worlds
        to run a batch of episodes in), which it declares with the class attribute
        ``config_table`` (a :class:`sitframe.contract.tables.ConfigTable`: the config
        checks, fills in and logs it) or, in the older form, names with the class
        attribute ``table``; a protocol with neither gets its defaults.

    All implementations are called; their lists are merged.
    """


# --------------------------------------------------------------------------
# Observer hooks
# --------------------------------------------------------------------------


@hookspec
def sitframe_run_start(run: RunInfo) -> None:
    """A run is starting.

    Called once, in the main process, after the config is resolved and before
    the first stage runs (for ``--resume``, before the missing trials run).

    :param run: What the run is: resolved config (text and dict), seed, output
        path, number of trials, plugin list, stages to run.

    All implementations are called; the return value is ignored.
    """


@hookspec
def sitframe_stage_end(run: RunInfo, stage: str, data: dict[str, Any]) -> None:
    """A non-learning stage finished (``"collect"``, ``"cluster"`` or ``"spaces"``).

    Called once per stage, in the main process.

    :param run: The run, as given to :func:`sitframe_run_start`.
    :param stage: ``"collect"``, ``"cluster"`` or ``"spaces"`` (the situation spaces of
        their own, ``[spaces.NAME]``: one entry per space with its ``state``, ``view``,
        ``readers``, ``labels``, ``source`` and, when fitted in the run, ``fit`` and its
        own ``samples``; written to ``/spaces/NAME``).
    :param data: The stage's results as numpy arrays and scalars (e.g.
        ``samples``, ``poses`` for collect; ``centers``, ``measures``,
        ``chosen`` for cluster), ready to be written.

    All implementations are called; the return value is ignored.
    """


@hookspec
def sitframe_step(record: StepRecord) -> None:
    """One control iteration finished.

    Called inside the simulation loop of the process that runs the trial (a
    worker process when trials run in parallel), after the behaviours learned
    from the iteration, once per iteration (each is 1.5 s of robot time),
    only if at least one plugin implements it. Not called in the evaluations
    of a learning trial (batches of an evaluation protocol's episodes);
    called in the episodes of a batch that is a trial of its own.

    :param record: An immutable :class:`sitframe.contract.records.StepRecord` holding
        references (not copies) to this iteration's arrays. Do not keep it
        beyond the call unless you copy what you need.

    A plugin implementing this hook sees every iteration from Python, so the trials of its
    runs take the Python loop instead of the compiled one (:mod:`sitframe.runs.fused`; the
    results are the same, some 4 times slower). To follow a run's progress, implement
    :func:`sitframe_progress`; to analyse iterations, read the log.

    All implementations are called; the return value is ignored.
    """


@hookspec
def sitframe_progress(trial: int, iterations: int) -> None:
    """Iterations of a trial finished: the hook for a progress display.

    Called in the process that runs the trial (a worker process when trials run in
    parallel) after every 100 iterations of the trial and after its last, in the trials in
    which :func:`sitframe_step` would be called (not in the evaluations of a learning trial).
    Unlike :func:`sitframe_step` it leaves a trial on its compiled path.

    :param trial: The trial's index.
    :param iterations: The iterations finished since the previous call for this trial
        (100, or the rest at the trial's end).

    All implementations are called; the return value is ignored.
    """


@hookspec
def sitframe_trial_data(trial: TrialResult) -> dict[str, Any] | None:
    """Hand per-trial data for the log.

    Called once per learning trial and once per evaluation episode (logged for
    a continuing protocol's, e.g. ``frozen``), in the process that simulated
    it (like :func:`sitframe_step`), right after the loop.

    :param trial: The finished :class:`sitframe.contract.records.TrialResult` (its
        per-iteration arrays, behaviour data and summary).
    :return: ``None``, or a dict of string keys (``/`` makes subgroups) to
        numpy arrays or scalars. The logger writes it under
        ``/trials/NNNN/plugins/<plugin>/`` in the same crash-safe transaction
        as the trial (an evaluation's under ``.../eval/<world>/``), and
        :meth:`sitframe.logs.reader.Log.trial` returns it as ``TrialLog.plugins``.

    Every implementation is called; each result is kept under its own plugin's
    name (a key handed twice by one plugin is an error).

    A trial longer than :func:`sitframe.scratch.limit` iterations has its arrays in
    scratch files (memory-mapped numpy arrays): read them a block of rows at a time to
    keep a long trial's memory flat; a whole copy (``np.array(arr)``) brings it back.
    """


@hookspec
def sitframe_trial_end(run: RunInfo, trial: TrialResult) -> None:
    """One learning trial (or a batch of an evaluation protocol's episodes) finished.

    Called in the main process, in trial order, with the complete per-iteration
    arrays of the trial, whether it was simulated here or in a worker.

    :param run: The run, as given to :func:`sitframe_run_start`.
    :param trial: The :class:`sitframe.contract.records.TrialResult`: seed, per-
        iteration arrays (a long trial's in scratch files, as for
        :func:`sitframe_trial_data`), per-behaviour learning data, learned policies,
        plugin data and summary scalars.
        An observer may add arrays for the log to
        ``trial.plugin_data["<its plugin name>"]`` here: the HDF5 logger's
        implementation runs last and writes them with the trial.

    All implementations are called; the return value is ignored.
    """


@hookspec
def sitframe_run_end(run: RunInfo, status: str) -> None:
    """A run ended.

    Called once in the main process, also when the run fails or is
    interrupted.

    :param run: The run, as given to :func:`sitframe_run_start`.
    :param status: ``"complete"``, ``"aborted"`` (interrupted, e.g. Ctrl-C) or
        ``"failed"`` (an error stopped it; ``run.extra["failure"]`` holds the
        one-line message when plugin code failed).

    All implementations are called; the return value is ignored.
    """
