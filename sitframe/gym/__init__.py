"""Gymnasium environments built from sitframe configs (extra ``gym``).

Install with ``pip install 'sitframe[gym]'``.

Importing this package registers three ids::

    import gymnasium as gym
    import sitframe.gym  # noqa: F401  (or gym.make("sitframe.gym:sitframe/ObstacleAvoidance-v0"))
    env = gym.make("sitframe/ObstacleAvoidance-v0")   # preset obstacle-avoidance
    env = gym.make("sitframe/WallFollowing-v0")       # preset wall-following
    env = gym.make("sitframe/GoalFinding-v0")         # preset goal-finding (goal-progress reward)

and :func:`make_env` makes one from any config (preset name or TOML path);
:class:`SitframeVectorEnv` steps N robots together.

What it holds
    :mod:`~sitframe.gym.task` (a config seen as a reinforcement-learning task: its
    spaces, reward, episode ends and the choices behind them, shared by both envs),
    :mod:`~sitframe.gym.env` (one robot, :class:`SitframeEnv`) and
    :mod:`~sitframe.gym.vector` (N robots stepped together, :class:`SitframeVectorEnv`).

What it may import
    :mod:`sitframe.contract` (a config resolved into its sensor, interpreter and reward),
    :mod:`sitframe.sim` (worlds, the robot, N robots stepped together) and the ground floor;
    never runs, logs or analysis (an environment is stepped by its learner, not run).

Entry points
    :func:`make_env`, :func:`make_vector_env`, :class:`SitframeEnv`,
    :class:`SitframeVectorEnv`, :class:`Task`, and the ids in :data:`ENV_IDS`.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from sitframe.gym.env import SitframeEnv
from sitframe.gym.task import Task
from sitframe.gym.vector import SitframeVectorEnv

__all__ = ["ENV_IDS", "SitframeEnv", "SitframeVectorEnv", "Task", "make_env", "make_vector_env"]

#: Registered id -> preset.
ENV_IDS = {
    "sitframe/ObstacleAvoidance-v0": "obstacle-avoidance",
    "sitframe/WallFollowing-v0": "wall-following",
    "sitframe/GoalFinding-v0": "goal-finding",
}


def make_env(config: str | dict[str, Any] = "obstacle-avoidance", **kwargs: Any) -> SitframeEnv:
    """A :class:`SitframeEnv` for ``config`` (preset name, TOML path or validated config dict).

    Keyword arguments are those of :class:`SitframeEnv` (``continuous``,
    ``render_mode``) and :meth:`Task.from_config` (``world``, ``reward``,
    ``reward_params``, ``max_steps``, ``normalize``, ``start_margin``,
    ``terminate_on_collision``, ``plugins_dirs``).
    """
    return SitframeEnv(config, **kwargs)


def make_vector_env(config: str | dict[str, Any] = "obstacle-avoidance", num_envs: int = 8,
                    **kwargs: Any) -> SitframeVectorEnv:
    """A :class:`SitframeVectorEnv` of ``num_envs`` robots for ``config`` (as :func:`make_env`)."""
    return SitframeVectorEnv(config, num_envs=num_envs, **kwargs)


for _id, _preset in ENV_IDS.items():
    if _id not in gym.registry:
        gym.register(_id, entry_point="sitframe.gym.env:SitframeEnv",
                     kwargs={"config": _preset}, vector_entry_point=
                     "sitframe.gym.vector:SitframeVectorEnv")
