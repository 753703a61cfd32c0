"""Write a :class:`~sitframe.analysis.compare.Comparison` as HTML, Markdown, CSV and figures.

``compare.md`` / ``compare.csv`` hold the table (CSV: one row per metric and
run, tidy), ``metrics.png`` every metric's trial values per run with the
estimate and its interval, and for a sweep ``axis_<key>.png`` each metric
against each grid axis. ``index.html`` shows them on one page (images are the
PNG files beside it).
"""

from __future__ import annotations

import csv
import math
import os
import re
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.analysis import html as H
from sitframe.analysis.compare import LEVEL, Comparison
from sitframe.errors import InputError

__all__ = ["write_comparison"]

_COLOURS = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#D55E00", "#56B4E9", "#000000",
            "#F0E442")


def _metric_panels(cmp: Comparison, row_height: float, extra: float) -> tuple[Any, np.ndarray]:
    """A figure with one titled panel per metric (``*`` when different), three per row."""
    from matplotlib.figure import Figure

    n = len(cmp.metrics)
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(4.0 * cols, row_height * rows + extra), layout="constrained")
    axs = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax, m in zip(axs, cmp.metrics, strict=False):
        ax.set_title(_wrap(m.label) + ("  *" if m.different else ""), fontsize=9)
        ax.tick_params(axis="y", labelsize=8)
        ax.grid(True, axis="y", color="0.9")
    for ax in axs[n:]:
        ax.set_visible(False)
    return fig, axs


def plot_metrics(cmp: Comparison, seed: int = 0) -> Any:
    """One panel per metric: trial values per run (dots), estimate and 95 % interval (bar)."""
    k = len(cmp.names)
    fig, axs = _metric_panels(cmp, 2.6 + 0.12 * k, 0.6)
    rng = np.random.default_rng(seed)
    for ax, m in zip(axs, cmp.metrics, strict=False):
        for j, v in enumerate(m.values):
            c = _COLOURS[j % len(_COLOURS)]
            ax.scatter(j + rng.uniform(-0.18, 0.18, v.size), v, s=9, color=c, alpha=0.35,
                       lw=0)
            if math.isfinite(m.estimate[j]):
                lo, hi = m.low[j], m.high[j]
                err = None if not (math.isfinite(lo) and math.isfinite(hi)) else \
                    [[m.estimate[j] - lo], [hi - m.estimate[j]]]
                ax.errorbar([j + 0.3], [m.estimate[j]], yerr=err, fmt="D", color=c, ms=5,
                            capsize=3, lw=1.5)
        if m.statistic == "share":
            ax.set_ylim(-0.05, 1.05)
        ax.set_xticks(range(k), [_wrap(n, 18) for n in cmp.names],
                      fontsize=7, rotation=30 if k > 3 else 0, ha="right" if k > 3 else "center")
        ax.set_xlim(-0.6, k - 0.3)
    fig.suptitle(f"Trial values (dots), median (share for convergence) and {LEVEL:.0%} "
                 f"bootstrap interval (diamond, bar); * = different at 5 % ({cmp.test}, Holm)",
                 fontsize=10)
    return fig


def _wrap(text: str, width: int = 34) -> str:
    return "\n".join(textwrap.wrap(text, width)) or text


def _axis_order(values: list[str]) -> list[str]:
    uniq = list(dict.fromkeys(values))
    try:
        return sorted(uniq, key=float)
    except ValueError:
        return uniq


def plot_axis(cmp: Comparison, key: str) -> Any:
    """Every metric against the sweep axis ``key``: one line per combination of the others."""
    xs = _axis_order([a[key] for a in cmp.axes.values()])
    others = [k for k in next(iter(cmp.axes.values())) if k != key]
    lines: dict[tuple[str, ...], dict[str, int]] = {}
    for j, name in enumerate(cmp.names):
        a = cmp.axes[name]
        lines.setdefault(tuple(a[k] for k in others), {})[a[key]] = j
    fig, axs = _metric_panels(cmp, 2.7, 0.9)
    for ax, m in zip(axs, cmp.metrics, strict=False):
        for li, (combo, idx) in enumerate(lines.items()):
            pos = [xs.index(x) + 0.06 * (li - (len(lines) - 1) / 2) for x in idx]
            js = list(idx.values())
            est = np.array([m.estimate[j] for j in js])
            lo = np.array([m.low[j] for j in js])
            hi = np.array([m.high[j] for j in js])
            err = np.vstack([np.nan_to_num(est - lo), np.nan_to_num(hi - est)])
            order = np.argsort(pos)
            label = ", ".join(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in
                              zip(others, combo, strict=True)) or None
            ax.errorbar(np.array(pos)[order], est[order], yerr=err[:, order], marker="o",
                        ms=4, capsize=3, lw=1.2, color=_COLOURS[li % len(_COLOURS)],
                        label=label)
        ax.set_xticks(range(len(xs)), xs, fontsize=8)
        ax.set_xlim(-0.5, len(xs) - 0.5)
        ax.set_xlabel(key, fontsize=8)
    handles, labels = axs[0].get_legend_handles_labels()
    if labels:
        fig.legend(handles, labels, loc="outside lower center", ncols=min(4, len(labels)),
                   fontsize=8, frameon=False)
    fig.suptitle(f"Metrics against {key}: median ({LEVEL:.0%} bootstrap interval), trials "
                 "pooled over seeds; * = settings differ at 5 % (Kruskal-Wallis, Holm)",
                 fontsize=10)
    return fig


def _write_csv(cmp: Comparison, path: Path) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["metric", "label", "run", "n", "statistic", "estimate", "low", "high",
                    "p", "p_holm", "different"])
        for m in cmp.metrics:
            for j, name in enumerate(cmp.names):
                w.writerow([m.key, m.label, name, m.values[j].size, m.statistic,
                            *(_cell(x) for x in (m.estimate[j], m.low[j], m.high[j], m.p,
                                                 m.p_holm)), int(m.different)])


def _cell(x: float) -> str:
    return repr(float(x)) if math.isfinite(x) else ""


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def write_comparison(cmp: Comparison, out_dir: str | os.PathLike[str], *, title: str,
                     dpi: int = 150) -> list[str]:
    """Write ``index.html``, ``compare.md``, ``compare.csv`` and the figures; return the paths."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc.strerror or exc}",
                         file=str(out), key="-o") from None
    table = cmp.table()
    figs: list[tuple[str, str]] = []
    try:
        plot_metrics(cmp).savefig(out / "metrics.png", dpi=dpi)
        figs.append(("metrics.png", "Every metric: the trial values of each run, the "
                     "estimate and its 95 % bootstrap interval"))
        for key in (next(iter(cmp.axes.values())) if cmp.axes else {}):
            name = f"axis_{_safe(key.rsplit('.', 1)[-1])}.png"
            plot_axis(cmp, key).savefig(out / name, dpi=dpi)
            figs.append((name, f"Every metric against {key} (one line per combination of the "
                         "other grid axes)"))
        (out / "compare.md").write_text(f"# {title}\n\n" + table.to_markdown()
                                        + "".join(f"\n![{c}]({f})\n" for f, c in figs),
                                        encoding="utf-8")
        _write_csv(cmp, out / "compare.csv")
        body = _html_body(cmp, table, figs, title)
        (out / "index.html").write_text(H.page(title, body), encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot write the comparison: {exc.strerror or exc}", file=str(out),
                         key="-o") from None
    return [str(out / n) for n in ("index.html", "compare.md", "compare.csv")] + \
        [str(out / f) for f, _ in figs]


def _html_body(cmp: Comparison, table: Any, figs: list[tuple[str, str]], title: str) -> str:
    src = "".join(f"<dt>{H.esc(n)}</dt><dd>{H.esc(s)}</dd>"
                  for n, s in zip(cmp.names, cmp.sources, strict=True))
    diff = [m.label for m in cmp.metrics if m.different]
    verdict = (f"<p><b>Different at the 5 % level</b> (Holm-adjusted {H.esc(cmp.test)}): "
               + H.esc(", ".join(diff)) + ".</p>") if diff else \
        f"<p><b>No metric differs at the 5 % level</b> (Holm-adjusted {H.esc(cmp.test)}).</p>"
    rows = [m.different for m in cmp.metrics]
    figures = "".join(f'<figure><img src="{H.esc(f)}" alt="{H.esc(c)}">'
                      f"<figcaption>{H.esc(c)}</figcaption></figure>" for f, c in figs)
    return (f"<h1>{H.esc(title)}</h1><dl class=\"meta\">{src}</dl>{verdict}"
            f"<h2>Metrics</h2>{H.table_html(table, table_id='comparison', highlight=rows)}"
            '<p class="note">Highlighted rows differ at the 5 % level. '
            '<a href="compare.csv">CSV</a> · <a href="compare.md">Markdown</a></p>'
            f"<h2>Figures</h2>{figures}")

