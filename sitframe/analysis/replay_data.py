"""The data behind the HTML report's interactive replay, packed small.

Every replayable episode of a log (each learning trial, and each trial's
frozen-policy evaluation in every evaluation world) is reduced to the arrays
the replay draws: pose, sensor reading, memberships, command, reward,
collisions with their contact points, the executed rule per situation, and in
goal episodes each iteration's goal.
Each array is quantised to integers at a fixed resolution (positions and
1 mm, heading 1 mrad, ranges 1/250 of the sensor's range (1.2 cm for
3 m), memberships 0.01, commands 0.1 deg and 1 mm/s,
reward 0.01), stored in the smallest integer type that holds it, and all
arrays are concatenated (4-byte aligned), gzip-compressed and base64-encoded
once. The page decompresses the blob with the browser's own
``DecompressionStream('gzip')`` and views each array as a typed array; the
JSON header says where each one is and its scale. An 11-trial log of 5000
iterations with 3 evaluations of 1000 iterations per trial packs to about
2 MB of base64.
"""

from __future__ import annotations

import base64
import gzip
from typing import Any

import numpy as np

from sitframe.analysis import results as R
from sitframe.errors import InputError
from sitframe.logs.reader import Log, TrialLog

__all__ = ["REPLAY_ARRAYS", "replay_payload"]

#: The per-iteration arrays an episode needs to be replayed.
REPLAY_ARRAYS = ("pose", "reading", "memberships", "command", "collision")

#: Array name -> quantisation scale (stored integer = round(value * scale)).
SCALES = {"pose_xy": 1000.0, "pose_th": 1000.0, "memberships": 100.0,
          "heading": 10.0, "speed": 1000.0, "reward": 100.0, "collision": 1.0,
          "contact": 1000.0, "rules": 1.0}
_INT_TYPES = (np.uint8, np.int8, np.uint16, np.int16, np.int32)
_JS_TYPES = {"uint8": "Uint8Array", "int8": "Int8Array", "uint16": "Uint16Array",
             "int16": "Int16Array", "int32": "Int32Array"}


class _Packer:
    """Concatenates quantised arrays into one buffer and remembers where each one is."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0

    def add(self, values: np.ndarray, scale: float) -> dict[str, Any]:
        """Quantise ``values`` (finite) and append them; return the JSON descriptor."""
        v = np.asarray(values, dtype=np.float64)
        if v.size and not np.isfinite(v).all():
            raise ValueError("replay arrays must be finite")
        q = np.rint(v * scale)
        lo, hi = (float(q.min()), float(q.max())) if q.size else (0.0, 0.0)
        kind = next(t for t in _INT_TYPES
                    if np.iinfo(t).min <= lo and hi <= np.iinfo(t).max)
        data = q.astype(np.dtype(kind).newbyteorder("<")).tobytes()
        desc = {"type": _JS_TYPES[np.dtype(kind).name], "offset": self.size,
                "shape": list(v.shape), "scale": scale}
        pad = (-len(data)) % 4  # typed-array views need aligned offsets
        self.parts.append(data + b"\0" * pad)
        self.size += len(data) + pad
        return desc

    def blob(self) -> str:
        return base64.b64encode(gzip.compress(b"".join(self.parts), compresslevel=6,
                                              mtime=0)).decode("ascii")


def _episode(P: _Packer, arrays: dict[str, np.ndarray], rules: np.ndarray | None,
             max_range: float) -> dict[str, Any] | None:
    if any(k not in arrays for k in REPLAY_ARRAYS):
        return None
    pose = np.asarray(arrays["pose"], dtype=np.float64)
    coll = np.asarray(arrays["collision"], dtype=bool)
    n = coll.size
    first = arrays.get("first_iteration")
    episode = None
    if first is not None and n:  # (a batch's extra row per episode: frames stay aligned)
        row, episode = R.episode_rows(n, first, pose.shape[0])
        pose = pose[np.append(row, row[-1] + 1)]
    reading = np.clip(np.nan_to_num(np.asarray(arrays["reading"], dtype=np.float64),
                                    nan=max_range, posinf=max_range), 0.0, max_range)
    cmd = np.nan_to_num(np.asarray(arrays["command"], dtype=np.float64))
    pts = R.collision_points(pose, np.flatnonzero(coll), arrays.get("contact"))
    theta = np.angle(np.exp(1j * pose[:, 2]))  # wrapped to (-pi, pi] so it fits int16 mrad
    out: dict[str, Any] = {
        "n": int(n),
        "xy": P.add(pose[:, :2], SCALES["pose_xy"]),
        "th": P.add(theta, SCALES["pose_th"]),
        "reading": P.add(reading, 250.0 / max_range),
        "memberships": P.add(np.clip(arrays["memberships"], 0.0, 1.0), SCALES["memberships"]),
        "heading": P.add(cmd[:, 0], SCALES["heading"]),
        "speed": P.add(cmd[:, 1], SCALES["speed"]),
        "collision": P.add(coll, 1.0),
        "contact": P.add(pts.reshape(-1, 2), SCALES["contact"]),
    }
    goals = arrays.get("goal")
    if episode is not None and goals is not None and np.ndim(goals) == 2 and \
            np.shape(goals)[1] >= 3 and len(goals) == len(first) and np.isfinite(goals).all():
        out["goal"] = P.add(np.asarray(goals, dtype=np.float64)[episode, :3],
                            SCALES["pose_xy"])  # (x, y, radius of the iteration's episode)
    rew = [k for k in arrays if k.startswith("reward/")]
    if rew:
        out["reward"] = P.add(np.nan_to_num(arrays[rew[0]]), SCALES["reward"])
        out["reward_label"] = rew[0].split("/", 1)[1]
    if rules is not None:
        out["rules"] = P.add(rules, 1.0)
    return out


def _policy(tr: TrialLog) -> tuple[dict[str, Any], np.ndarray | None, np.ndarray | None]:
    """The learned output of a trial: its descriptor (``behaviour``, ``output``, ``actions``,
    ``unit``), its rule indices per iteration (L, c) if logged, and its final ones (1, c).
    Without a learned output: ``({}, None, None)``."""
    try:
        label, output = R.learned_output(tr)
    except InputError:
        return {}, None, None
    po = tr.policies[label].outputs[output]
    per_it = tr.behaviours[label].get(f"{output}/rule_base")
    return ({"behaviour": label, "output": output,
             "actions": np.asarray(po.actions, dtype=np.float64).tolist(), "unit": po.unit},
            None if per_it is None else np.asarray(per_it), np.asarray(po.rules)[None, :])


def replay_payload(log: Log, trials: dict[int, TrialLog]) -> dict[str, Any]:
    """Header (JSON-able) and packed arrays of every replayable episode of ``trials``.

    Parameters
    ----------
    log
        The log (for worlds, sensor geometry, robot radius, situation labels).
    trials
        Trial index -> trial, as read with :meth:`sitframe.logs.reader.Log.trial`.

    Returns
    -------
    dict
        ``worlds`` (name -> walls, obstacles, bounds, goal), ``sensor``
        (``angles_deg``, ``max_range``), ``radius`` [m], ``labels`` (one per
        situation), ``episodes`` (list of descriptors: ``trial``, ``kind``
        ``"learning"``/``"evaluation"`` (``"run"`` for a trial of a run
        without the learn stage), ``world``, ``n``, ``convergence``,
        ``actions`` and ``unit`` of the learned output, and one
        ``{type, offset, shape, scale}`` per array) and ``blob`` (base64 of
        the gzip-compressed arrays).
    """
    spec = log.sensor
    try:  # a run without the learn stage (e.g. goal episodes with a frozen rule base)
        learns = log.learned
    except InputError:
        learns = True
    P = _Packer()
    episodes: list[dict[str, Any]] = []
    for k in sorted(trials):
        tr = trials[k]
        policy, per_it, frozen = _policy(tr)
        conv = R.convergence_iteration(tr)
        # the rule per situation: per iteration while learning, the frozen policy otherwise
        own = per_it if per_it is not None else (None if learns else frozen)
        pre = "learn/" if learns else ""  # (a learning chain's episodes, or a batch's)
        own_arrays = {**tr.arrays, **{k: tr.episodes[pre + k] for k in ("first_iteration",
                                                                        "goal")
                                      if pre + k in tr.episodes}}
        runs: list[tuple[str, str, dict[str, np.ndarray], np.ndarray | None]] = [
            ("learning" if learns else "run", tr.world, own_arrays, own)]
        runs += [("evaluation", w, arrays, frozen)
                 for w, arrays in R.evaluation_episodes(tr).items()]
        for kind, world, arrays, rules in runs:
            if rules is not None and rules.ndim != 2:
                rules = None
            ep = _episode(P, arrays, rules, spec.max_range)
            if ep is None:
                continue
            ep.update(trial=k, kind=kind, world=world,
                      convergence=conv if kind == "learning" else None, **policy)
            episodes.append(ep)
    worlds = {name: {"walls": [np.round(a, 3).tolist() for a in w.walls],
                     "obstacles": [np.round(a, 3).tolist() for a in w.obstacles],
                     "bounds": [float(b) for b in w.bounds],
                     "goal": None if w.goal is None else
                     [*map(float, w.goal.position), float(w.goal.radius)]}
              for name, w in R.parsed_worlds(log).items()}  # (a damaged world: left out)
    labels = R.situation_labels(log)
    return {"worlds": worlds, "episodes": episodes, "radius": R.robot_radius(log),
            "sensor": {"angles_deg": spec.angles_deg.tolist(), "max_range": spec.max_range},
            "labels": labels, "blob": P.blob(), "raw_bytes": P.size}

