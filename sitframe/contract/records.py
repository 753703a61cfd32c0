"""Immutable records passed between the run driver and components.

They hold references to arrays the loop already computed (no copies), so they
are cheap to build every iteration. Treat every array in them as read-only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from sitframe.sim.fastinit import record

if TYPE_CHECKING:
    from sitframe.sim.robot import Command, StepOutcome
    from sitframe.sim.world import Goal, World


@record
class Proposal:
    """What one behaviour wants: a relative heading change and optionally a speed.

    Attributes
    ----------
    heading_deg
        Relative heading change in degrees, positive = left (CCW), in [-90, 90].
    speed_m_s
        Desired speed in m/s, or ``None`` for "no opinion" (the arbiter then
        uses the run's default speed).
    activation
        How much the behaviour's own situation applies now, in [0, 1] (e.g. 1
        when an avoider sees an obstacle it must turn from, 0 in open space),
        or ``None`` when the behaviour does not say. Arbiters may use it: the
        ``priority`` arbiter lets a behaviour with an activation win when the
        activation reaches its rule's ``activation_above``.
    """

    heading_deg: float
    speed_m_s: float | None = None
    activation: float | None = None

    @staticmethod
    def blend(proposals: list[Proposal], weights: Any) -> Proposal:
        """The weighted fusion of ``proposals`` (CDB's, and any arbiter's that blends).

        The heading is ``sum_k w_k heading_k``; the speed is the weighted mean over
        the proposals that have one (``None`` if none has, or their weights are 0).
        """
        pairs = list(zip(weights, proposals, strict=True))
        heading = float(sum(wk * p.heading_deg for wk, p in pairs))
        sw = sum(wk for wk, p in pairs if p.speed_m_s is not None)
        speed = None
        if sw > 0:
            speed = float(sum(wk * p.speed_m_s for wk, p in pairs if p.speed_m_s is not None)
                          / sw)
        return Proposal(heading, speed)


@record
class Context:
    """What every behaviour and arbiter sees at one iteration.

    Attributes
    ----------
    iteration
        0-based control iteration within the trial (each is 1.5 s by default).
    pose
        (3,) x [m], y [m], theta [rad].
    reading
        (d,) sensor reading, metres (e.g. the 8 sonar ranges from the rim).
    memberships
        (c,) memberships of the reading to the fuzzy situations (sum 1), or an
        empty array when the run has no interpreter.
    nearest
        Smallest entry of ``reading``, metres.
    world
        The world the robot is in.
    goal
        The current episode's goal (an evaluation protocol's, e.g. goal
        episodes), else the world's ``[goal]``, else ``None``.
    spaces
        In a run with situation spaces of their own (``[spaces.NAME]``): space
        name -> (c,) memberships of each space (``"default"``: the
        ``[interpreter]``'s), the same for every component; ``memberships`` is
        then those of the space the component reads (its table's ``space``).
        ``None`` in a run with one space (``memberships`` is its only one).
    """

    iteration: int
    pose: np.ndarray
    reading: np.ndarray
    memberships: np.ndarray
    nearest: float
    world: World
    goal: Goal | None = None
    spaces: dict[str, np.ndarray] | None = None


@record
class Transition:
    """One iteration's cause and effect, given to rewards and learning behaviours.

    Attributes
    ----------
    before, after
        Context at the start of the iteration and at the start of the next.
    command
        The command the robot executed (after arbitration and clipping).
    outcome
        The simulator's :class:`sitframe.sim.robot.StepOutcome` (collision, contact,
        distance, poses).
    """

    before: Context
    command: Command
    outcome: StepOutcome
    after: Context

    @property
    def collided(self) -> bool:
        return bool(self.outcome.collided)


@record
class StepRecord:
    """Everything about one iteration, for ``sitframe_step`` observers."""

    trial: int
    transition: Transition
    proposals: dict[str, Proposal]
    weights: np.ndarray
    rewards: dict[str, float]


@dataclass
class RunInfo:
    """Describes a run to observers.

    Attributes
    ----------
    name
        Experiment name (preset name or config file stem).
    config
        The fully resolved config as a dict.
    config_text
        The same config rendered as TOML text (written to the log).
    config_hash
        SHA-256 of ``config_text``.
    seed
        The run seed; trial seeds are spawned from it.
    out
        Path of the HDF5 log, or ``None``.
    n_trials
        Number of learning trials (or episode batches) in the run.
    iterations
        Iterations per trial.
    plugins
        ``[{"name", "origin", "distribution", "version", "file"}]``.
    worlds
        World name -> TOML text of every world the run uses.
    extra
        Free-form metadata observers may read (e.g. ``"show_progress"``).
    """

    name: str
    config: dict[str, Any]
    config_text: str
    config_hash: str
    seed: int
    out: str | None
    n_trials: int
    iterations: int
    plugins: list[dict[str, Any]] = field(default_factory=list)
    worlds: dict[str, str] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class TrialResult:
    """A finished trial: per-iteration arrays, behaviour data and summary scalars.

    Attributes
    ----------
    index
        0-based trial number.
    seed
        The trial's seed entropy (spawned from the run seed).
    world
        Name of the world the trial ran in.
    arrays
        Per-iteration arrays, all of length ``iterations``: ``pose (L, 3)``,
        ``sonar (L, d)``, ``memberships (L, c)``, ``command (L, 2)``,
        ``collision (L,)``, ``contact (L, 2)``, ``nearest (L,)``,
        ``weights (L, k)``, ``proposals/<label> (L, 2)``,
        ``reward/<label> (L,)``.
    behaviours
        Behaviour label -> what its ``trial_data()`` returned.
    summary
        Scalars for the summary table (``converged``, ``convergence_iteration``,
        ``collisions``, ``collisions_after_convergence``, ...).
    episodes
        Per-episode figures of a batch of an evaluation protocol's episodes (e.g.
        ``success``, ``iterations``), and evaluations (``eval/<world>/...``).
    policies
        Behaviour label -> the :class:`LearnedPolicy` it ended the trial with
        (learned behaviours only); the arbiter's, if it learns, under the
        label ``"arbiter"``.
    plugin_data
        Plugin name -> arrays/scalars that plugin handed for the trial
        (component ``trial_end`` or observer ``sitframe_trial_data``); written
        to ``/trials/NNNN/plugins/<plugin>/``.
    situations
        Only with an evolving interpreter: ``state`` (the final situations, a
        state its ``load_state`` takes), ``events`` (the history, arrays of
        :func:`sitframe.situations.events.history_arrays`) and ``count``; written to
        ``/trials/NNNN/situations/``.
    """

    index: int
    seed: int
    world: str
    arrays: dict[str, np.ndarray]
    behaviours: dict[str, dict[str, Any]]
    summary: dict[str, Any]
    episodes: dict[str, np.ndarray] = field(default_factory=dict)
    policies: dict[str, LearnedPolicy] = field(default_factory=dict)
    plugin_data: dict[str, dict[str, Any]] = field(default_factory=dict)
    situations: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SensorSpec:
    """The geometry of a sensor's reading, known before anything runs.

    Read from the sensor component when the run is resolved (its ``angles_deg``,
    ``max_range`` and ``unit``), handed to every component in :class:`RunContext` and
    written to the log, so a reader knows the reading's layout without the plugin.

    Attributes
    ----------
    name
        The sensor's registry name, e.g. ``"pioneer-sonar"``.
    angles_deg
        (d,) bearing of each beam relative to the robot's heading [deg],
        positive = left; any layout (a front arc, a 360 deg ring).
    max_range
        Largest reading [m]; a beam that sees nothing reads this.
    unit
        Unit of the reading's entries (``"m"`` for range sensors).
    """

    name: str
    angles_deg: np.ndarray
    max_range: float
    unit: str = "m"

    @property
    def dim(self) -> int:
        """Length ``d`` of one reading."""
        return int(self.angles_deg.size)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (the log's ``sensor`` root attribute)."""
        return {"name": self.name, "angles_deg": [float(a) for a in self.angles_deg],
                "max_range": float(self.max_range), "unit": self.unit, "dim": self.dim}


@dataclass(frozen=True)
class SpaceInfo:
    """One situation space of a run (``[interpreter]`` or a ``[spaces.NAME]`` table).

    Attributes
    ----------
    name
        ``"default"`` (the ``[interpreter]``) or the table's name.
    n_situations
        Its number of situations (``None`` until fitted, e.g. ``c = "auto"``).
    view
        (d',) indices of the sensor's readings it sees (all, in order, for the default).
    readers
        The behaviour labels (and ``"arbiter"``) that read it.
    """

    name: str
    n_situations: int | None
    view: tuple[int, ...]
    readers: tuple[str, ...]


@dataclass(frozen=True)
class RunContext:
    """What a run is, given to every component's optional ``bind(run)`` before anything runs.

    Attributes
    ----------
    robot
        The robot's :class:`sitframe.sim.robot.RobotParams` (``radius`` [m],
        ``control_period_s``, speed and turn limits).
    sensor
        The run sensor's :class:`SensorSpec`.
    labels
        Behaviour labels in config order (the order of proposals and weights).
    n_situations
        Number of situations the interpreter produces (``None`` when the
        interpreter cannot say before it is fitted).
    worlds
        Name -> :class:`sitframe.sim.world.World` of every world the run uses.
    seed
        The run seed.
    iterations
        Iterations per learning trial.
    default_speed
        Speed [m/s] used when no behaviour proposes one.
    component
        The config key of the component being bound (``"sensor"``,
        ``"behaviours.avoid"``, ``"behaviours.avoid.reward"``, ``"arbiter"``),
        so one class can serve several roles.
    tables
        The run's plugin-declared config tables, as validated with their defaults
        (table name -> key -> value; :mod:`sitframe.contract.tables`): where a component
        that declares a ``config_table`` reads it.
    space
        The situation space the component reads (its table's ``space``,
        default ``"default"``: the ``[interpreter]``); ``n_situations`` is that
        space's. A reward is bound with its behaviour's space.
    spaces
        Every situation space of the run: name -> its :class:`SpaceInfo`.
    """

    robot: Any
    sensor: SensorSpec
    labels: tuple[str, ...]
    n_situations: int | None
    worlds: dict[str, Any]
    seed: int
    iterations: int
    default_speed: float
    component: str = ""
    tables: dict[str, dict[str, Any]] = field(default_factory=dict)
    space: str = "default"
    spaces: dict[str, SpaceInfo] = field(default_factory=dict)


@dataclass(frozen=True)
class TrialInfo:
    """One trial about to run (or just finished), given to ``trial_start``/``trial_end``.

    Attributes
    ----------
    index
        0-based trial number (evaluations share their learning trial's index).
    kind
        ``"learn"`` (a learning trial) or ``"evaluate"`` (a frozen policy run,
        e.g. in another world or a goal episode).
    world
        The world the trial runs in.
    iterations
        At most this many control iterations.
    rng
        The trial's generator: take all randomness from it.
    """

    index: int
    kind: str
    world: Any
    iterations: int
    rng: np.random.Generator


@dataclass(frozen=True)
class PolicyOutput:
    """One learned output of a situation rule base.

    Attributes
    ----------
    actions
        (A,) the action values the rules choose from (e.g. headings [deg]).
    rules
        (c,) index into ``actions`` chosen for each situation.
    unit
        Unit of ``actions`` (``"deg"``, ``"m/s"``, or ``""`` for a weighting).
    q
        (c, A) action values, if the learner keeps them, else ``None``.
    """

    actions: np.ndarray
    rules: np.ndarray
    unit: str = ""
    q: np.ndarray | None = None

    def __post_init__(self) -> None:
        a = np.asarray(self.actions, dtype=np.float64).reshape(-1)
        r = np.asarray(self.rules)
        if r.ndim != 1 or (r.size and not np.issubdtype(r.dtype, np.integer)):
            raise TypeError(f"PolicyOutput.rules must be a 1-D integer array, got {r.dtype} "
                            f"shape {r.shape}")
        if r.size and (r.min() < 0 or r.max() >= a.size):
            raise ValueError(f"PolicyOutput.rules index {a.size} actions but holds values "
                             f"{int(r.min())}..{int(r.max())}")
        if self.q is not None and np.shape(self.q) != (r.size, a.size):
            raise ValueError(f"PolicyOutput.q must be (c, A) = ({r.size}, {a.size}), got "
                             f"{np.shape(self.q)}")
        object.__setattr__(self, "actions", a)
        object.__setattr__(self, "rules", r)

    def values(self) -> np.ndarray:
        """(c,) the action value of each situation's rule."""
        return self.actions[np.asarray(self.rules, dtype=np.intp)]


@dataclass(frozen=True)
class LearnedPolicy:
    """What a learned behaviour (or arbiter) learned: one rule base per output.

    A behaviour that learns returns one from ``policy()`` after a trial; the
    core logs it (``policy/<output>``, ``actions/<output>``, ``q/<output>``
    under the behaviour's group), and ``run --json``, the run table,
    ``evaluate``, ``policy_from``, ``analyse`` and ``replay`` read it back for
    any behaviour. ``load_policy`` receives one to freeze the behaviour.

    Attributes
    ----------
    outputs
        Output name (e.g. ``"heading"``, ``"speed"``) -> :class:`PolicyOutput`.
    """

    outputs: dict[str, PolicyOutput]

    def __post_init__(self) -> None:
        if not isinstance(self.outputs, dict) or not all(
                isinstance(k, str) and k and "/" not in k and isinstance(o, PolicyOutput)
                for k, o in self.outputs.items()):
            raise TypeError(f"LearnedPolicy.outputs must be a dict of output names (non-empty, "
                            f"no '/') to PolicyOutput, got {self.outputs!r:.80}")

    def rules(self) -> dict[str, np.ndarray]:
        """Output -> (c,) action indices (the form ``policy_from`` loads)."""
        return {k: o.rules for k, o in self.outputs.items()}


def summary_key(*parts: str, sep: str = "/") -> str:
    """The one spelling of a summary key, e.g. ``summary_key("eval", "novel-1", "coverage")``.

    The parts are joined by ``sep``: ``"/"`` in a trial's summary
    (:attr:`TrialResult.summary`, ``run --json``), ``"."`` in the log's summary
    table and ``Log.summary()`` (an HDF5 name cannot hold ``/``), ``"_"`` in a
    sweep's CSV columns (headers that spreadsheets read unquoted).
    """
    return sep.join(parts)
