"""A sweep's summary tables: each point's medians and IQRs, pooled over seeds, as CSV and
Markdown (``summary.csv``, ``summary.md``, ``summary-pooled.md`` in the sweep's folder).

Columns are spelled by :func:`sitframe.contract.records.summary_key` with ``"_"`` (headers a
spreadsheet reads unquoted): e.g. ``eval_novel-1_coll_median``.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.contract.records import summary_key
from sitframe.logs.reader import open_log


def format_value(v: Any) -> str:
    """A config value as it appears in point names and table cells (one spelling per value)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        short = f"{v:g}"
        return short if float(short) == v else repr(v)  # never two values, one name
    if isinstance(v, list | tuple):
        return "-".join(format_value(x) for x in v)
    if isinstance(v, dict):  # a component table: its component, then its parameters
        return " ".join([str(v.get("component", "default")),
                         *(f"{k}={format_value(x)}" for k, x in v.items() if k != "component")])
    return str(v)


def _median_iqr(x: np.ndarray) -> tuple[float, float, float]:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan, math.nan
    q25, q50, q75 = np.percentile(x, [25, 50, 75])
    return float(q50), float(q25), float(q75)


def summarise_tables(tables: list[np.ndarray], *, learned: bool = True) -> dict[str, Any]:
    """Statistics of the trials in one or more logs' summary tables, pooled.

    Medians and IQRs as in the module docstring; for every evaluation world
    also the worst trial (``eval_<w>_coll_max``) and the share of trials above
    10 collisions per 1000 (``eval_<w>_coll_over10``). ``learned=False`` (runs
    without a ``learn`` stage, e.g. goal episodes of frozen behaviours) makes
    ``convergence_rate`` NaN, shown as "–": nothing was learned, so "0 of N
    converged" would be untrue.
    """
    n = sum(len(t) for t in tables)
    row: dict[str, Any] = {"trials": n}

    def col(name: str) -> np.ndarray:
        parts = [np.asarray(t[name], float) if name in (t.dtype.names or ())
                 else np.full(len(t), np.nan) for t in tables]
        return np.concatenate(parts) if parts else np.empty(0)

    conv = col("converged") > 0.5
    row["convergence_rate"] = float(conv.mean()) if n and learned else math.nan
    it = col("convergence_iteration")[conv]
    row["conv_iter_median"], row["conv_iter_q25"], row["conv_iter_q75"] = _median_iqr(it)
    post = col("collisions_per_1000_after_convergence")[conv]
    row["post_coll_median"], row["post_coll_q25"], row["post_coll_q75"] = _median_iqr(post)
    worlds = list(dict.fromkeys(m.group(1) for t in tables for name in t.dtype.names or ()
                                if (m := re.fullmatch(r"eval\.(.+)\.collisions_per_1000", name))))
    for w in worlds:
        c = col(summary_key("eval", w, "collisions_per_1000", sep="."))
        k = summary_key("eval", w, "coll", sep="_")
        fin = c[np.isfinite(c)]
        row[f"{k}_median"], row[f"{k}_q25"], row[f"{k}_q75"] = _median_iqr(c)
        row[f"{k}_max"] = float(fin.max()) if fin.size else math.nan
        row[f"{k}_over10"] = float(np.mean(fin > 10)) if fin.size else math.nan
        row[summary_key("eval", w, "coverage_median", sep="_")] = \
            _median_iqr(col(summary_key("eval", w, "coverage", sep=".")))[0]
    row["eval_worlds"] = worlds
    row["eval_scores"] = scores = _protocol_scores(tables)
    for w, keys in scores.items():
        for key in keys:
            c = col(summary_key("eval", w, key, sep="."))
            pre = summary_key("eval", w, key, sep="_")
            row[f"{pre}_median"], row[f"{pre}_q25"], row[f"{pre}_q75"] = _median_iqr(c)
    return row


#: Evaluation figures every evaluation has (the frozen run's); the others in a summary
#: table (``eval.<world>.<key>``) are an episode protocol's scores, e.g. ``success_rate``.
_FROZEN_KEYS = ("iterations", "collisions", "collisions_per_1000", "distance_m",
                "mean_speed_m_s", "coverage", "episodes")


def _protocol_scores(tables: list[np.ndarray]) -> dict[str, list[str]]:
    """World -> the episode protocol's score keys in the tables, in order of appearance."""
    out: dict[str, list[str]] = {}
    for t in tables:
        for name in t.dtype.names or ():
            m = re.fullmatch(r"eval\.(.+)\.([^.]+)", name)
            if m and m.group(2) not in _FROZEN_KEYS and t[name].dtype.kind in "fiub":
                keys = out.setdefault(m.group(1), [])
                if m.group(2) not in keys:
                    keys.append(m.group(2))
    return out


def summarise_log(path: str | Path) -> dict[str, Any]:
    """Per-point statistics from a log's summary table (see the module docstring)."""

    log = open_log(path)
    return {"log": str(path), "status": log.status,
            **summarise_tables([log.summary()], learned=log.learned)}


SEED_KEY = "experiment.seed"


def pool_over_seeds(result: dict[str, Any]) -> list[dict[str, Any]]:
    """Rows pooled over the run seeds, when the grid varies ``experiment.seed``.

    Points that differ only in the seed form one row whose statistics are
    over all their trials (``seeds`` tells how many runs); an empty list when
    the grid has no seed axis.
    """

    keys = result["keys"]
    if SEED_KEY not in keys:
        return []
    others = [k for k in keys if k != SEED_KEY]
    groups: dict[tuple[str, ...], list[dict[str, Any]]] = {}
    for r in result["points"]:
        groups.setdefault(tuple(format_value(r[k]) for k in others), []).append(r)
    rows = []
    for members in groups.values():
        logs = [open_log(r["log"]) for r in members]
        tables = [lg.summary() for lg in logs]
        first = members[0]
        rows.append({"point": ", ".join(f"{k}={format_value(first[k])}" for k in others) or "all",
                     **{k: first[k] for k in others}, "seeds": len(members),
                     "status": "complete" if all(r["status"] == "complete" for r in members)
                     else "incomplete",
                     **summarise_tables(tables, learned=any(lg.learned for lg in logs))})
    return rows


def _num(v: Any, digits: int = 1) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def _med_iqr(row: dict[str, Any], prefix: str, digits: int) -> str:
    med = row[f"{prefix}_median"]
    if not math.isfinite(med):
        return "–"
    return (f"{_num(med, digits)} [{_num(row[f'{prefix}_q25'], digits)}, "
            f"{_num(row[f'{prefix}_q75'], digits)}]")


def _eval_worlds(rows: list[dict[str, Any]]) -> list[str]:
    """Every evaluation world of the points, in order of first appearance."""
    return list(dict.fromkeys(w for r in rows for w in r["eval_worlds"]))


def write_tables(result: dict[str, Any], out: Path) -> tuple[Path, Path]:
    """Write ``summary.csv`` and ``summary.md`` for a sweep result; return their paths."""
    rows = result["points"]
    keys = result["keys"]
    worlds = _eval_worlds(rows)
    cols = ["point", *keys, "trials", "status", "convergence_rate", "conv_iter_median",
            "conv_iter_q25", "conv_iter_q75", "post_coll_median", "post_coll_q25",
            "post_coll_q75"]
    for w in worlds:
        cols += [summary_key("eval", w, s, sep="_") for s in (
            "coll_median", "coll_q25", "coll_q75", "coll_max", "coll_over10", "coverage_median")]
    out.mkdir(parents=True, exist_ok=True)
    csv_path, md_path = out / "summary.csv", out / "summary.md"
    _write_csv(csv_path, rows, [*cols, "log"])
    md_path.write_text(markdown_table(result), encoding="utf-8")
    if result.get("pooled"):
        pcols = ["point", *[k for k in keys if k != SEED_KEY], "seeds", *cols[len(keys) + 1:]]
        _write_csv(out / "summary-pooled.csv", result["pooled"], pcols)
        (out / "summary-pooled.md").write_text(markdown_table(result, pooled=True),
                                               encoding="utf-8")
    return csv_path, md_path


def _write_csv(path: Path, rows: list[dict[str, Any]], cols: list[str]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in rows:
            w.writerow(["" if (isinstance(r.get(c), float) and not math.isfinite(r[c]))
                        else r.get(c, "") for c in cols])


def markdown_table(result: dict[str, Any], *, pooled: bool = False) -> str:
    """The sweep's summary as a Markdown table (one row per point).

    With ``pooled=True``, the rows of :func:`pool_over_seeds` (one per setting,
    over all seeds) instead.
    """
    rows = result["pooled"] if pooled else result["points"]
    keys = [k for k in result["keys"] if not (pooled and k == SEED_KEY)]
    worlds = _eval_worlds(rows)
    short = [k.rsplit(".", 1)[-1] for k in keys]
    head = [*short, *(["seeds"] if pooled else []), "trials", "converged",
            "iterations to conv., median [IQR]", "coll./1000 after conv., median [IQR]"]
    for w in worlds:
        head += [f"{w}: coll./1000 median [IQR] (worst)", f"{w}: > 10", f"{w}: coverage"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in rows:
        cells = [format_value(r[k]) for k in keys]
        if pooled:
            cells.append(str(r["seeds"]))
        n = r["trials"]
        rate = r["convergence_rate"]
        cells.append(str(n))
        cells.append(f"{round(rate * n)}/{n}" if n and math.isfinite(rate) else "–")
        cells.append(_med_iqr(r, "conv_iter", 0))
        cells.append(_med_iqr(r, "post_coll", 1))
        for w in worlds:
            k = summary_key("eval", w, "coll", sep="_")
            cells.append(f"{_med_iqr(r, k, 1)} ({_num(r.get(f'{k}_max', math.nan), 0)})")
            over = r.get(f"{k}_over10", math.nan)
            cells.append(f"{over:.0%}" if math.isfinite(over) else "–")
            cov = summary_key("eval", w, "coverage_median", sep="_")
            cells.append(_num(r.get(cov, math.nan), 2))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n" + _scores_table(rows, keys, pooled)


def _scores_table(rows: list[dict[str, Any]], keys: list[str], pooled: bool) -> str:
    """The episode protocol's scores (goal episodes: success, SPL, ...), median [IQR] over
    the trials, one line per point and world; empty when no evaluation had a protocol."""
    worlds = list(dict.fromkeys(w for r in rows for w in r.get("eval_scores", {})))
    if not worlds:
        return ""
    names = list(dict.fromkeys(k for r in rows for ks in r["eval_scores"].values() for k in ks))
    head = [*(k.rsplit(".", 1)[-1] for k in keys), *(["seeds"] if pooled else []), "world",
            *names]
    lines = ["", "Episode scores, median [IQR] over the trials:", "",
             "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in rows:
        for w in worlds:
            if w not in r.get("eval_scores", {}):
                continue
            cells = [format_value(r[k]) for k in keys] + ([str(r["seeds"])] if pooled else [])
            cells.append(w)
            for name in names:
                pre = summary_key("eval", w, name, sep="_")
                cells.append(_med_iqr(r, pre, 2) if f"{pre}_median" in r else "–")
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
