"""A frozen Stable-Baselines3 policy as a behaviour (``sb3-policy``; extra ``baselines``).

Loads a model saved by SB3 (``model.save("avoid.zip")``), trained on a
:mod:`sitframe.gym` environment, and proposes its action every iteration, so
a run scores it with exactly the metrics of a fuzzy rule base (its learning
trial drives it frozen; the evaluate stage scores it in ``[evaluate] worlds``)
and an arbiter can fuse it with other behaviours (e.g. CDB with ``goal``).
Stable-Baselines3 and torch are imported only when a config uses this
behaviour; without them the config fails in one line naming the extra.

The observation is built as the env built it (:meth:`sitframe.gym.task.Task.observe`):
the reading, divided by the sensor's ``max_range`` when ``normalize`` (the env's
default), plus the goal's distance and bearing when the model was trained on a
goal task (its observation has two more entries than the sensor has beams;
``diagonal`` is then the training world's bounding-box diagonal the distance
was divided by). Its action is mapped back as the env mapped it: a discrete
index over ``headings`` x ``speeds``, or a continuous heading (and speed).

Config::

    [behaviours.avoid]
    component = "sb3-policy"
    model = "models/dqn-avoid.zip"          # relative to the working folder
    algorithm = "dqn"                       # dqn ppo a2c sac td3 ddpg
    headings = [90, 60, 30, 0, -30, -60, -90]
    speeds = []                             # as in the env's config
    normalize = true

The policy is the model file: a run records the file's SHA-256 in each trial's
behaviour data (``params/sha256``, under ``/trials/NNNN/behaviours/<label>/``),
and ``sitframe evaluate`` re-creates the behaviour with it (``sha256 = ...``),
so a log is re-scored with the very policy that ran, or refused in one line
when the file is missing or has changed since. A config may pin ``sha256``
itself.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

import numpy as np

from sitframe import Context, Proposal, RunContext, Transition, hookimpl
from sitframe import params as P

ALGORITHMS = ("dqn", "ppo", "a2c", "sac", "td3", "ddpg")


class SB3PolicyBehaviour:
    """Propose the action of a frozen SB3 model (module docstring)."""

    name = "sb3-policy"

    def __init__(self, *, model: str, algorithm: str = "dqn",
                 headings: list[float] = (90, 60, 30, 0, -30, -60, -90),  # type: ignore[assignment]
                 speeds: list[float] = (),  # type: ignore[assignment]
                 normalize: bool = True, diagonal: float = 0.0, sha256: str = "") -> None:
        P.choice("algorithm", algorithm, ALGORITHMS)
        self.headings = np.asarray(P.number_list("headings", list(headings), lo=-90, hi=90,
                                                 unit="deg"))
        self.speeds = np.asarray(P.number_list("speeds", list(speeds), lo=0.0,
                                               unit="m/s")) if len(speeds) \
            else np.empty(0)
        self.normalize = bool(normalize)
        self.diagonal = P.number("diagonal", diagonal, lo=0.0)
        if not Path(model).is_file():
            raise ValueError(f"model: file not found: {model!r} (expected a model saved by "
                             "Stable-Baselines3, e.g. model.save('avoid.zip'))")
        self.sha256 = hashlib.sha256(Path(model).read_bytes()).hexdigest()
        if sha256 and sha256 != self.sha256:
            raise ValueError(f"model: {model!r} has changed since the run (its SHA-256 is "
                             f"{self.sha256[:16]}..., the run's was {str(sha256)[:16]}...); "
                             "expected the model file the run used")
        try:
            import stable_baselines3 as sb3
        except ImportError:
            raise ValueError("needs Stable-Baselines3 and torch, which are not installed: "
                             "pip install 'sitframe[baselines]'") from None
        try:
            self.model = getattr(sb3, algorithm.upper()).load(model, device="cpu")
        except Exception as exc:  # noqa: BLE001 - any loader failure is the model file's
            raise ValueError(f"model: cannot load {model!r} as {algorithm.upper()}: "
                             f"{type(exc).__name__}: {exc}") from None
        obs, act = self.model.observation_space, self.model.action_space
        self.discrete = hasattr(act, "n")
        n_act = self.headings.size * max(1, self.speeds.size)
        if self.discrete and int(act.n) != n_act:
            raise ValueError(f"the model has {act.n} discrete actions but headings x speeds "
                             f"gives {n_act}; configure the headings/speeds of its env")
        self.obs_dim = int(np.prod(obs.shape))
        self._robot: Any = None

    def bind(self, run: RunContext) -> None:
        """Check the model's observation against the run's sensor."""
        d = run.sensor.dim
        if self.obs_dim not in (d, d + 2):
            raise ValueError(f"the model observes {self.obs_dim} values but the sensor has {d} "
                             f"beams; expected {d} (or {d + 2} with a goal)")
        if self.obs_dim == d + 2 and self.normalize and self.diagonal <= 0:
            raise ValueError("diagonal: a normalised goal model needs the training world's "
                             "bounding-box diagonal [m] (the distance was divided by it)")
        self.max_range = float(run.sensor.max_range)
        self._robot = run.robot

    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        pass

    def observation(self, context: Context) -> np.ndarray:
        """The env's observation of ``context`` (float32)."""
        r = np.asarray(context.reading, dtype=np.float64)
        obs = r / self.max_range if self.normalize else r
        if self.obs_dim == r.size + 2:
            if context.goal is None:
                raise ValueError("the model was trained with a goal but the context has none")
            gx, gy = context.goal.position
            p = context.pose
            dist = math.hypot(gx - p[0], gy - p[1])
            bearing = math.remainder(math.atan2(gy - p[1], gx - p[0]) - p[2], 2.0 * math.pi)
            extra = (min(dist, self.diagonal) / self.diagonal, bearing / math.pi) \
                if self.normalize else (dist, bearing)
            obs = np.concatenate([obs, extra])
        return obs.astype(np.float32)

    def propose(self, context: Context) -> Proposal:
        act, _ = self.model.predict(self.observation(context), deterministic=True)
        if self.discrete:
            i = int(np.asarray(act).reshape(-1)[0])
            v = max(1, self.speeds.size)
            return Proposal(float(self.headings[i // v]),
                            float(self.speeds[i % v]) if self.speeds.size else None)
        a = np.clip(np.asarray(act, dtype=np.float64).reshape(-1), -1.0, 1.0)
        rp = self._robot
        speed = rp.min_speed + 0.5 * (a[1] + 1.0) * (rp.max_speed - rp.min_speed) \
            if a.size > 1 else None
        return Proposal(float(a[0]) * rp.max_heading_change_deg, speed)

    def learn(self, transition: Transition, reward: float) -> None:
        pass  # frozen

    def trial_data(self) -> dict[str, Any]:
        """The model file's SHA-256, a parameter ``sitframe evaluate`` re-creates it with."""
        return {"params/sha256": self.sha256}


@hookimpl
def sitframe_behaviours() -> list[Any]:
    return [SB3PolicyBehaviour]
