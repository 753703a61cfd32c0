"""The small interfaces every component satisfies.

Plugins contribute *factories* (usually classes) through the registration
hooks in :mod:`sitframe.contract.hookspecs`; the core creates one instance per trial
from the run config and calls the methods below directly in its loop. These
are :class:`typing.Protocol` classes: implement the methods, no inheritance
needed. See ``plugins/`` for a worked example of each, and ``docs/tutorials/plugins.md``.

Lifecycle, for every kind (each step optional unless the protocol lists it)::

    factory(**params)          # created from the config table; ValueError/TypeError
                               # become one line naming the file and key
    bind(run: RunContext)      # once, before collect: robot, sensor spec, labels,
                               # number of situations, worlds, seed
    trial_start(trial: TrialInfo)   # each learning trial and each evaluation
    ... the loop ...
    trial_end(trial: TrialInfo) -> dict | None
                               # arrays/scalars to log under plugins/<plugin>/

The core checks each component against its protocol when it is created (a
missing method is one line naming plugin, component and method) and checks
every value that crosses the boundary (:mod:`sitframe.contract`); an exception
raised in a component during a run is reported as one line naming the plugin,
the component, the method, the trial and the iteration.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from sitframe.contract.records import Context, LearnedPolicy, Proposal, Transition
    from sitframe.sim.robot import RobotParams
    from sitframe.sim.world import World


@runtime_checkable
class Sensor(Protocol):
    """Turns the world and a pose into one reading.

    Attributes
    ----------
    name
        Unique registry name, e.g. ``"pioneer-sonar"``.
    angles_deg
        (d,) bearing of each beam relative to the robot's heading, degrees,
        positive = left.
    max_range
        Largest reading, metres.
    """

    name: ClassVar[str]
    angles_deg: np.ndarray
    max_range: float

    def read(self, world: World, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Return the (d,) reading (metres) for ``pose`` = (x [m], y [m], theta [rad]).

        Must be a float array of exactly ``len(angles_deg)`` ranges in [0, max_range]
        (checked). The run logs readings as ``reading`` with this geometry
        (:class:`sitframe.contract.records.SensorSpec`), whatever the sensor.
        """
        ...


@runtime_checkable
class SituationInterpreter(Protocol):
    """Turns a reading into memberships of ``n_situations`` fuzzy situations.

    **Evolving situations** (optional extension, :mod:`sitframe.situations`).
    An interpreter with the class attribute ``evolving = True`` may create,
    split, merge and prune situations during a learning trial. Then
    ``n_situations`` is its *capacity* (situation ids ``0 .. c - 1``, given
    in order and never reused; memberships are 0 for ids not alive), and it
    has ``events() -> list[SituationEvent]`` (drained by the core after each
    learning iteration and handed to every behaviour's optional
    ``situations_changed(event)``), optionally ``observe_errors(errors)``
    (the learners' per-situation absolute TD errors, see
    :meth:`Behaviour.situation_errors`) and optionally ``rules_converged()`` (called
    once in a learning trial, after the iteration at which every learning behaviour's
    :meth:`Behaviour.learning_converged` first holds; an interpreter may stop changing
    its situations from then on). It must not change in a frozen
    evaluation (``trial_start`` with kind ``"evaluate"``); its ``state()``
    after a learning trial is that trial's own final situations, logged under
    ``/trials/NNNN/situations`` and used by the trial's evaluations and by
    ``sitframe evaluate LOG --trial K``. Without a cluster stage (and without
    ``clusters_from``) the run starts from its unfitted ``state()``.
    """

    name: ClassVar[str]

    @property
    def n_situations(self) -> int:
        """Number ``c`` of situations (known from the config, before ``fit``; ``None`` if
        only ``fit`` decides it, e.g. ``c = "auto"``; an evolving interpreter's capacity)."""
        ...

    def fit(self, X: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
        """Fit on collected readings ``X`` (n, d); return arrays/scalars to log.

        An interpreter whose ``fit`` also accepts a keyword ``pmap`` is given
        the run's parallel map (:class:`sitframe.situations.clustering.TaskMap`) when the
        run has a worker pool, and may spread independent work (e.g. FCM
        trials) over it; the result must not depend on whether it did.
        """
        ...

    def memberships(self, reading: np.ndarray) -> np.ndarray:
        """Return the (c,) memberships of one (d,) reading: non-negative, summing to 1 (checked)."""
        ...

    def state(self) -> dict[str, Any]:
        """The fitted state as arrays/scalars (written to the log)."""
        ...

    def load_state(self, state: dict[str, Any]) -> None:
        """Restore a state returned by :meth:`state` (read back from a log)."""
        ...


@runtime_checkable
class Reward(Protocol):
    """Maps one transition to a scalar reward: a finite real number (checked).

    A stateful reward resets its state in ``trial_start(trial)`` and reads the
    robot's radius or the sensor geometry from ``bind(run)``.

    Optional: a method ``metrics(arrays) -> dict[str, float]`` that scores a
    finished trial's per-iteration arrays (``pose``, ``sonar``, ``command``,
    ``collision``, ... as in the log) by the behaviour's own measure of
    quality. :func:`sitframe.runs.evaluation.evaluate_log` adds what it returns to
    every evaluation (the wall-following reward reports
    ``wall_band_fraction`` this way). It is not part of the protocol check.
    """

    name: ClassVar[str]

    def __call__(self, transition: Transition) -> float: ...


@runtime_checkable
class Behaviour(Protocol):
    """Proposes a heading change (and optionally a speed) each iteration.

    Lifecycle per trial: [``load_policy``] → ``reset`` → ``trial_start`` →
    (``propose`` → ``learn``)* → ``trial_data`` → ``policy`` → ``trial_end``.
    ``learn`` is required, and called, only when the behaviour has a reward
    bound in the config and the trial learns; ``load_policy`` only when the
    config gives it a policy (``policy_from``) or a frozen evaluation runs.

    **Its situations.** A behaviour reads the situation space its table names
    (``space = "NAME"``, a ``[spaces.NAME]`` table: situations of its own over
    the readings of that space's ``view``), else the ``[interpreter]``'s: the
    core hands it that space's number of situations (``bind``: ``run.space``,
    ``run.n_situations``; ``reset``) and memberships (``context.memberships``
    in ``propose``, in ``learn``'s transition and its reward's), so a behaviour
    needs no code of its own to read situations of its own; ``context.spaces``
    holds every space's memberships by name in a run with more than one. Its
    ``policy()`` has one rule per situation of its space.

    A *learned* behaviour is one whose ``policy()`` returns a
    :class:`sitframe.contract.records.LearnedPolicy` (actions, output names and units,
    the per-situation rules, optionally Q). The core logs it and every tool
    (run table, ``--json``, ``evaluate``, ``policy_from``, ``analyse``,
    ``replay``) reads it from there, so a new learned behaviour is as
    visible as the built-in ``fuzzy-q``.
    """

    name: ClassVar[str]

    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        """Start a trial of at most ``iterations`` iterations."""
        ...

    def propose(self, context: Context) -> Proposal: ...

    def learn(self, transition: Transition, reward: float) -> None: ...

    def trial_data(self) -> dict[str, Any]:
        """Optional. Arrays (per-iteration or snapshots) and scalars to log for the trial.

        Scalars named ``converged`` (bool) and ``convergence_iteration`` (int,
        -1 if not converged) are used by the summary table and ``run --json``.
        Scalars named ``params/<key>`` are parameters the behaviour ran with beyond
        its config table (a frozen policy's model-file hash): ``sitframe evaluate``
        re-creates it with them.
        Written under ``/trials/NNNN/behaviours/<label>/``.
        """
        ...

    def policy(self) -> LearnedPolicy | None:
        """Optional. The policy learned in the trial that just ended (``None``: nothing learned)."""
        ...

    def situations_changed(self, event: Any) -> None:
        """Optional. The interpreter's situations changed (evolving interpreters only).

        ``event`` is a :class:`sitframe.situations.events.SituationEvent`: a situation
        ``event.id`` was created or split off (initialise its per-situation
        state from ``event.parents`` weighted by ``event.weights``), merged
        (``event.removed`` absorbed into ``event.id``) or pruned. Called after
        ``learn`` and before the next ``propose``; events come in order.
        """
        ...

    def learning_converged(self) -> bool:
        """Optional. Whether this behaviour's learning has converged (its rule base is
        frozen for the rest of the trial).

        Asked after ``learn`` in every learning iteration of a run whose interpreter is
        evolving and has ``rules_converged()``, until every behaviour and learning arbiter
        that has this method says ``True``; the interpreter is then told once."""
        ...

    def situation_errors(self) -> np.ndarray | None:
        """Optional. (c,) absolute TD errors the last ``learn`` attributed to each situation
        (0 where nothing was updated); an evolving interpreter splits where they stay large.

        Called after ``learn`` in every learning iteration of a run whose interpreter is
        evolving. ``None`` means no errors this time. Anything but ``None`` or a (c,)
        numeric array of finite values >= 0 is a fault of this behaviour."""
        ...

    def load_policy(self, policy: LearnedPolicy) -> None:
        """Optional. Fix (part of) the behaviour to a learned policy read back from a log.

        Called before :meth:`reset`, e.g. to evaluate a frozen rule base or to
        hold the heading rule base fixed while speed is learned. Outputs the
        behaviour does not have may be ignored; actions that differ from the
        behaviour's own should be refused (``ValueError``).
        """
        ...


@runtime_checkable
class Arbiter(Protocol):
    """Fuses the behaviours' proposals into one command.

    ``bind(run)`` gives the behaviour labels (``run.labels``) before anything
    runs: check the arbiter's rules against them there, so a typo is one line
    before collect starts. An arbiter may *learn* as a behaviour does: give it
    ``reward = "..."`` (and ``reward_params``) in ``[arbiter]`` and a method
    ``learn(transition, reward)``; it may also have ``reset``, ``policy`` and
    ``load_policy`` (a learned policy is logged under the label ``arbiter``).
    It reads a situation space of its own as a behaviour does (``space`` in
    ``[arbiter]``). Its policy is a situation rule base like a behaviour's: every output
    holds one rule per situation of its space, shape (c,); an arbiter whose state adds a
    context to the situations logs one output per context (``fuzzy-q-arbiter``:
    ``ahead``, ``left``, ..., ``right_stalled``). A policy over another state
    (e.g. the goal's bearing alone) is refused at the end of the first trial,
    in one line; such an arbiter keeps what it learned in ``trial_data()``.
    """

    name: ClassVar[str]

    def combine(
        self, context: Context, proposals: dict[str, Proposal]
    ) -> tuple[Proposal, np.ndarray]:
        """Return the fused proposal and the (k,) weight given to each proposal, in order.

        Weights are finite and non-negative: how much each proposal counted,
        logged as ``trials/K/weights`` (the built-in arbiters normalise them to
        sum 1; the core does not require it). A negative or non-finite weight
        ends the run with a one-line plugin error.

        A fused speed of ``None`` means the run's ``experiment.default_speed``.
        The run driver clips the result to the robot's limits.
        """
        ...


@runtime_checkable
class EvaluationProtocol(Protocol):
    """How the evaluate stage runs and scores episodes of the frozen behaviours.

    A run uses the protocol a component names in its class attribute
    ``evaluation_protocol``, else ``frozen`` (``plugins/frozen_evaluation.py``).
    The protocol is created from its config table (its keys but ``worlds``), declared
    with the class attribute ``config_table`` (:class:`sitframe.contract.tables.ConfigTable`:
    the config checks each key, fills in the defaults and logs the table; the built-in
    ``[evaluate]`` and ``[goal]`` are declared so) or named by :attr:`table` alone (its
    keys are then the keyword arguments); a protocol with no table gets its defaults.
    The evaluate stage runs one *batch* of episodes in each world
    of that table's ``worlds``: a trial of its own in a run that does not
    learn, else an evaluation of each learning trial with that trial's learned
    policies. The core runs every episode through the one simulation loop,
    without learning; a batch is logged as one trial (episodes concatenated,
    ``first_iteration`` gives each one's first row) with the per-episode
    figures under ``episodes/``, the core's figures (:data:`sitframe.runs.loop.EVAL_KEYS`)
    and the aggregates as ``eval/<world>/<key>`` summary scalars.

    Attributes
    ----------
    name
        Unique registry name, e.g. ``"goal-episodes"``.
    table
        Optional: the config table holding the parameters, e.g. ``"goal"`` (the name of
        its ``config_table``, if it declares one).
    config_table
        Optional: the declaration of that table (keys, types, defaults, ranges).
    iterations
        The iteration limit of an episode (Gymnasium's *truncation*).

    Notes
    -----
    An optional ``check_world(world)`` raises :class:`sitframe.errors.InputError`
    for a world the protocol cannot use, before anything runs. A parameter
    ``episodes`` (episodes per batch) is what ``sitframe evaluate LOG
    --goal-episodes N`` sets. A protocol with a true ``train_in_episodes`` attribute
    makes each learning trial a chain of its episodes; an optional
    ``training_starts(world, rng, robot)`` (as :meth:`episode_starts`) then draws
    the training pairs instead (a curriculum). :meth:`score_episode`,
    :meth:`aggregate` are optional;
    ``episodic = False`` (*continuing*): a batch is one run on its own seed, not logged per episode.
    """

    name: ClassVar[str]
    iterations: int

    def episode_starts(self, world: World, rng: np.random.Generator,
                       robot: RobotParams) -> tuple[np.ndarray, np.ndarray | None]:
        """The batch's start poses (n, 3: x [m], y [m], theta [rad]) and goals (n, 3: x [m],
        y [m], radius [m]; ``None``: no goals), drawn from ``rng`` (seeded per batch)."""
        ...

    def terminated(self, context: Context) -> bool:
        """Whether the episode ends at ``context`` (e.g. the goal is reached), checked after
        every iteration."""
        ...

    def score_episode(self, arrays: dict[str, np.ndarray], start: np.ndarray,
                      goal: np.ndarray | None, robot: RobotParams) -> dict[str, Any]:
        """Figures of one finished episode (scalars, the same keys for every episode) from its
        per-iteration arrays (``pose`` (n+1, 3), ``collision``, ``command``, ...)."""
        ...

    def aggregate(self, figures: dict[str, np.ndarray]) -> dict[str, float]:
        """The batch's scores from the per-episode figures (one array per key)."""
        ...
