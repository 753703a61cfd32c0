"""The ``frozen`` evaluation protocol: one run of the frozen behaviours from the world's start.

The evaluate stage's default: a run whose components name no other
``evaluation_protocol`` evaluates each learning trial's frozen (learned)
policy in every world of ``[evaluate] worlds`` with one run from the
world's start pose (and its ``[goal]``, if any, in the context), without
learning, truncated after ``[evaluate] iterations`` (default 1000); nothing
terminates it early. A run that does not learn runs it with the policies it
was given (``policy_from``), one trial per world.

It is a *continuing* protocol (:attr:`FrozenEvaluation.episodic` is False):
the run is not an episode among others but the evaluation itself, so it
runs on the evaluation's own seed and is logged as one run, with no
per-episode records. Its scores are the figures the core measures of every
evaluation (:data:`sitframe.runs.loop.EVAL_KEYS`): ``iterations``,
``collisions``, ``collisions_per_1000``, ``distance_m``,
``mean_speed_m_s`` and ``coverage`` (the fraction of free 0.5 m grid cells
the robot's centre visited), as ``eval/<world>/<key>``; it adds no
per-episode figures or aggregates of its own.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from sitframe import ConfigKey, ConfigTable, Context, RobotParams, World, hookimpl
from sitframe import params as P

#: The ``[evaluate]`` table: declared here, as a third-party protocol declares its own.
#: ``always``: every config holds it (it did before protocols declared their tables).
EVALUATE = ConfigTable("evaluate", (
    ConfigKey("worlds", "names", ["training", "novel-1", "novel-2"],
              "the worlds each learning trial's frozen rule base is evaluated in"),
    ConfigKey("iterations", "integer", 1000, "the length of each evaluation run", lo=1,
              hi=10_000_000),
), "The default evaluation: one run of the frozen behaviours from each world's start "
   "(the frozen protocol).", always=True)


class FrozenEvaluation:
    """One run from the world's start (module docstring): the ``[evaluate]`` table's parameters.

    Parameters
    ----------
    iterations
        Length of the run (Gymnasium's truncation), in control iterations.
    """

    name = "frozen"
    table: ClassVar[str] = "evaluate"
    config_table: ClassVar[ConfigTable] = EVALUATE
    episodic: ClassVar[bool] = False

    def __init__(self, *, iterations: int = 1000) -> None:
        self.iterations = int(P.number("iterations", iterations, lo=1, integer=True))

    def episode_starts(self, world: World, rng: np.random.Generator,
                       robot: RobotParams) -> tuple[np.ndarray, None]:
        """The world's start pose (1, 3); no goal (the world's ``[goal]`` stays in the context)."""
        return np.asarray(world.start, dtype=float)[None, :], None

    def terminated(self, context: Context) -> bool:
        """Never: the run lasts its ``iterations``."""
        return False

    def _fused(self) -> dict[str, Any] | None:
        """What the compiled trial needs of the protocol (``sitframe.runs.fused``): nothing
        ends a run early, so it runs compiled without calling :meth:`terminated`; ``None``
        for a subclass with a ``terminated`` of its own."""
        if type(self).terminated is not FrozenEvaluation.terminated:
            return None
        return {"terminates": False}


@hookimpl
def sitframe_protocols() -> list[Any]:
    return [FrozenEvaluation]
