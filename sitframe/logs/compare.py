"""Two logs compared bit for bit: every dataset, group and attribute below the root.

How a refactor or a parallel run proves itself: the same seed gives the same log
(``compare_logs(a, b) == []``). Root attributes describe the run (its time, status,
versions), not its results, and are left out.
"""

from __future__ import annotations

import os
from typing import Any


def log_contents(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Every dataset and group of an HDF5 log and every attribute below the root, by path.

    Root attributes are left out: they describe the run (``created``,
    ``status``), not its results. Trial attributes (index, seed, world, and
    the summary scalars) are included as ``"<group>@<attr>"``; a group is
    included as ``"<group>/"`` (value ``None``), so an empty group counts too.
    """
    import h5py

    out: dict[str, Any] = {}
    with h5py.File(path, "r") as f:
        def visit(name: str, obj: Any) -> None:
            if isinstance(obj, h5py.Dataset):
                out[name] = obj[()]
            else:
                out[f"{name}/"] = None
            for k, v in obj.attrs.items():
                out[f"{name}@{k}"] = v
        f.visititems(visit)  # hard links only; trials not yet packed are in their own files:
        trials = f.get("trials")
        for t in trials if isinstance(trials, h5py.Group) else ():
            if isinstance(trials.get(t, getlink=True), h5py.ExternalLink):
                visit(f"trials/{t}", trials[t])
                trials[t].visititems(lambda n, o, t=t: visit(f"trials/{t}/{n}", o))
    return out


def compare_logs(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> list[str]:
    """Paths whose contents differ between two logs, bit for bit (empty = identical).

    Compares every dataset (dtype, shape and bytes) and every non-root
    attribute, and which groups exist, as :func:`log_contents` lists them.
    Variable-length strings (object arrays) are compared by value, since their
    bytes are pointers.
    """
    import numpy as np

    ca, cb = log_contents(a), log_contents(b)
    diff = sorted(set(ca) ^ set(cb))
    for key in sorted(set(ca) & set(cb)):
        x, y = np.asarray(ca[key]), np.asarray(cb[key])
        same = x.dtype == y.dtype and x.shape == y.shape and (
            x.tolist() == y.tolist() if x.dtype.kind == "O" else x.tobytes() == y.tobytes())
        if not same:
            diff.append(key)
    return diff
