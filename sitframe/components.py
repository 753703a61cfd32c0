"""The small interfaces every component satisfies.

Plugins contribute *factories* (usually classes) through the registration
hooks in :mod:`sitframe.hookspecs`; the scheduler creates one instance per
trial from the run config and then calls the methods below directly in its
loop. These are :class:`typing.Protocol` classes: implement the methods, no
inheritance needed. See ``plugins/`` for a worked example of each.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from sitframe.records import Context, Proposal, Transition
    from sitframe.world import World


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
        """Return the (d,) reading (metres) for ``pose`` = (x [m], y [m], theta [rad])."""
        ...


@runtime_checkable
class SituationInterpreter(Protocol):
    """Turns a reading into memberships of ``n_situations`` fuzzy situations."""

    name: ClassVar[str]

    @property
    def n_situations(self) -> int: ...

    def fit(self, X: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
        """Fit on collected readings ``X`` (n, d); return arrays/scalars to log.

        An interpreter whose ``fit`` also accepts a keyword ``pmap`` is given
        the run's parallel map (:class:`sitframe.clustering.TaskMap`) when the
        run has a worker pool, and may spread independent work (e.g. FCM
        trials) over it; the result must not depend on whether it did.
        """
        ...

    def memberships(self, reading: np.ndarray) -> np.ndarray:
        """Return the (c,) memberships of one (d,) reading; they sum to 1."""
        ...

    def state(self) -> dict[str, Any]:
        """The fitted state as arrays/scalars (written to the log)."""
        ...

    def load_state(self, state: dict[str, Any]) -> None:
        """Restore a state returned by :meth:`state` (read back from a log)."""
        ...


@runtime_checkable
class Reward(Protocol):
    """Maps one transition to a scalar reward.

    Optional: a method ``metrics(arrays) -> dict[str, float]`` that scores a
    finished trial's per-iteration arrays (``pose``, ``sonar``, ``command``,
    ``collision``, ... as in the log) by the behaviour's own measure of
    quality. :func:`sitframe.experiment.evaluate_log` adds what it returns to
    every evaluation (the wall-following reward reports
    ``wall_band_fraction`` this way). It is not part of the protocol check.
    """

    name: ClassVar[str]

    def __call__(self, transition: Transition) -> float: ...


@runtime_checkable
class Behaviour(Protocol):
    """Proposes a heading change (and optionally a speed) each iteration.

    Lifecycle per trial: [``load_policy``] → ``reset`` → (``propose`` → ``learn``)*
    → ``trial_data``.
    ``learn`` is called only when the behaviour has a reward bound in the
    config and ``learning`` is on.
    """

    name: ClassVar[str]

    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        """Start a trial of at most ``iterations`` iterations."""
        ...

    def propose(self, context: Context) -> Proposal: ...

    def learn(self, transition: Transition, reward: float) -> None: ...

    def trial_data(self) -> dict[str, Any]:
        """Arrays (per-iteration or snapshots) and scalars to log for the trial.

        Scalars named ``converged`` and ``convergence_iteration`` are used by
        the summary table and ``run --json``; a learned policy is returned
        under ``policy/...`` keys and read back by :meth:`load_policy`.
        """
        ...

    def load_policy(self, policy: dict[str, np.ndarray]) -> None:
        """Fix (part of) the behaviour to a learned policy read back from a log.

        Called before :meth:`reset`, e.g. to evaluate a frozen rule base or to
        hold the heading rule base fixed while speed is learned.
        """
        ...


@runtime_checkable
class Arbiter(Protocol):
    """Fuses the behaviours' proposals into one command."""

    name: ClassVar[str]

    def combine(
        self, context: Context, proposals: dict[str, Proposal]
    ) -> tuple[Proposal, np.ndarray]:
        """Return the fused proposal and the (k,) weight given to each proposal, in order.

        A fused speed of ``None`` means the run's ``experiment.default_speed``.
        The scheduler clips the result to the robot's limits.
        """
        ...
