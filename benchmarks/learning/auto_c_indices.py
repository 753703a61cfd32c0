"""Which c would each cluster-validity index choose, run by run?

Question: Which number of situations would each cluster-validity index choose, run by run?
Output: one row per log with each index's pick, printed.

Run::

    python benchmarks/learning/auto_c_indices.py logs/sweeps/situations/*c=auto*.h5

For every log given (it needs the ``collect`` stage), the collected readings
are mapped to the interpreter's feature space (its ``transform`` and
``offset``) and clustered for each c in ``--cs`` by
:func:`sitframe.situations.clustering.sweep_c` (``--restarts`` FCM runs per c, one chosen
as in the run). Each index then picks a c:

``R_f`` (minimise; sitframe's ``c = "auto"`` rule, thesis Eq. 4.9)
    fuzzy over non-fuzzy members; clusters that end up empty are skipped.
``XB`` (minimise; Xie & Beni 1991)
    ``J_m / (n min_{s != t} |v_s - v_t|^2)``: compactness over separation.
``FS`` (minimise; Fukuyama & Sugeno 1989)
    ``J_m - sum_is u_is^m |v_s - mean(x)|^2``.
``PBMF`` (maximise; Pakhira, Bandyopadhyay & Maulik 2004)
    ``(E_1 / E_c * max_{s,t} |v_s - v_t| / c)^2`` with ``E_1`` the summed
    distance to the data mean and ``E_c = sum_is u_is^m |x_i - v_s|``.

Prints each log's picks and, per index, the picks over all logs. An index
whose picks scatter across the candidates from one run seed to the next
cannot choose c for the learner; the fixed-c sweep's evaluation collisions
(README, "Situations") say which c is best.
"""

from __future__ import annotations

import argparse

import numpy as np

from sitframe.logs.reader import open_log
from sitframe.situations.clustering import sweep_c
from sitframe.situations.fcm import memberships

MINIMISE = {"R_f": True, "XB": True, "FS": True, "PBMF": False}


def indices(F: np.ndarray, V: np.ndarray, m: float, rf: float) -> dict[str, float]:
    """The four indices of one partition: samples ``F`` (n, d), prototypes ``V`` (c, d)."""
    um = memberships(F, V, m) ** m                      # (n, c)
    d2 = ((F[:, None, :] - V[None]) ** 2).sum(axis=-1)  # (n, c)
    jm = float((um * d2).sum())
    vv = ((V[:, None] - V[None]) ** 2).sum(axis=-1)     # (c, c)
    mean = F.mean(axis=0)
    e1 = float(np.sqrt(((F - mean) ** 2).sum(axis=-1)).sum())
    ec = float((um * np.sqrt(d2)).sum())
    return {"R_f": rf,
            "XB": jm / (len(F) * vv[~np.eye(len(V), dtype=bool)].min()),
            "FS": jm - float((um * ((V - mean) ** 2).sum(axis=-1)[None]).sum()),
            "PBMF": (e1 / ec * np.sqrt(vv.max()) / len(V)) ** 2}


def picks(path: str, cs: list[int], restarts: int, seed: int) -> dict[str, int]:
    """Each index's c for the readings collected in the log at ``path``."""
    log = open_log(path)
    cfg = log.config["interpreter"]
    X = np.asarray(log.stage("collect")["samples"], dtype=float)
    offset = float(cfg.get("offset", 0.1))
    F = {"log": lambda r: np.log(r + offset),
         "inverse": lambda r: 1.0 / (r + offset)}.get(cfg.get("transform", "range"),
                                                       lambda r: r)(X)
    m = float(cfg.get("m", 1.2))
    sw = sweep_c(F, cs, n_trials=restarts, m=m, seed=np.random.default_rng(seed))
    rows = []
    for k, c in enumerate(sw.cs):
        rf = float(sw.measures["rf"][k]) if sw.measures["min_card"][k] > 0 else np.inf
        rows.append(indices(F, np.asarray(sw.centers(int(c))), m, rf))
    out = {}
    for name, lower in MINIMISE.items():
        v = np.array([r[name] for r in rows])
        out[name] = int(sw.cs[int(np.argmin(v) if lower else np.argmax(v))])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="logs with a collect stage (one per run seed)")
    ap.add_argument("--cs", type=int, nargs="+", default=list(range(4, 21, 2)))
    ap.add_argument("--restarts", type=int, default=10, help="FCM runs per c")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    every = [picks(p, args.cs, args.restarts, args.seed) for p in args.logs]
    for p, row in zip(args.logs, every, strict=True):
        print(p, " ".join(f"{k}={v}" for k, v in row.items()))
    for name in MINIMISE:
        c = np.array([row[name] for row in every])
        print(f"{name}: picks {c.tolist()}; median {np.median(c):g}, range {c.min()}-{c.max()}")


if __name__ == "__main__":
    main()
