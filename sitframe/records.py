"""Immutable records passed between the scheduler and components.

They hold references to arrays the loop already computed (no copies), so they
are cheap to build every iteration. Treat every array in them as read-only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from sitframe.robot import Command, StepOutcome
    from sitframe.world import Goal, World


@dataclass(frozen=True, slots=True)
class Proposal:
    """What one behaviour wants: a relative heading change and optionally a speed.

    Attributes
    ----------
    heading_deg
        Relative heading change in degrees, positive = left (CCW), in [-90, 90].
    speed_m_s
        Desired speed in m/s, or ``None`` for "no opinion" (the arbiter then
        uses the run's default speed).
    """

    heading_deg: float
    speed_m_s: float | None = None


@dataclass(frozen=True, slots=True)
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
        The current goal (goal episodes), else ``None``.
    """

    iteration: int
    pose: np.ndarray
    reading: np.ndarray
    memberships: np.ndarray
    nearest: float
    world: World
    goal: Goal | None = None


@dataclass(frozen=True, slots=True)
class Transition:
    """One iteration's cause and effect, given to rewards and learning behaviours.

    Attributes
    ----------
    before, after
        Context at the start of the iteration and at the start of the next.
    command
        The command the robot executed (after arbitration and clipping).
    outcome
        The simulator's :class:`sitframe.robot.StepOutcome` (collision, contact,
        distance, poses).
    """

    before: Context
    command: Command
    outcome: StepOutcome
    after: Context

    @property
    def collided(self) -> bool:
        return bool(self.outcome.collided)


@dataclass(frozen=True, slots=True)
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
        Per-episode arrays for goal runs (``success``, ``iterations``, ...), else empty.
    """

    index: int
    seed: int
    world: str
    arrays: dict[str, np.ndarray]
    behaviours: dict[str, dict[str, Any]]
    summary: dict[str, Any]
    episodes: dict[str, np.ndarray] = field(default_factory=dict)
