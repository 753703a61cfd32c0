"""``index.html`` of ``sitframe analyse``: the whole analysis on one page, with a replay.

The page holds the run's metadata, warnings (incomplete log, figures that
could not be made, a plugin failure), every figure (``<img>`` of the PNG
beside the page) and table of the analysis, the config, the plugin list,
and an interactive replay (``templates/replay.js``) of every learning trial
and every frozen-policy evaluation: world, path so far, sensor beams,
membership of each situation with its rule's action, command, reward and
collisions; play/pause, speed, trail length, a slider to scrub, the trial and
the episode chosen from the page. The replay's arrays are embedded once,
quantised and gzip-compressed (:mod:`sitframe.analysis.replay_data`); the
page needs no network and opens from ``file://``.
"""

from __future__ import annotations

import os
from itertools import groupby
from typing import Any

from sitframe.analysis import html as H
from sitframe.analysis.replay_data import replay_payload
from sitframe.analysis.results import Table
from sitframe.logs.reader import Log, TrialLog

__all__ = ["write_report_html"]

_SPEEDS = (1, 2, 5, 10, 25, 50, 100, 250)  # iterations per second
_TRAILS = (("all", "whole path"), ("500", "last 500"), ("100", "last 100"), ("20", "last 20"))


def _meta(lg: Log, rep: Any) -> str:
    a = lg.attrs
    rows = [("log", lg.path), ("experiment", a.get("name", "?")),
            ("created", a.get("created", "?")), ("seed", a.get("seed", "?")),
            ("status", lg.status),
            ("finished trials", f"{len(lg.trial_indices())}"
             + (f" of {a['n_trials']}" if "n_trials" in a else "")),
            ("iterations per trial", a.get("iterations", "?")),
            ("config hash", a.get("config_hash", "?")), ("source", a.get("source", "") or "–")]
    try:
        rows.append(("versions", ", ".join(f"{k} {v}" for k, v in lg.versions.items())))
    except Exception:  # noqa: BLE001 - a damaged attribute is reported in the warnings
        pass
    if rep.trials:
        rows.append(("per-trial figures", "trial " + ", ".join(map(str, rep.trials))
                     + " (default: the converged trial with the median convergence iteration)"))
    return '<dl class="meta">' + "".join(f"<dt>{H.esc(k)}</dt><dd>{H.esc(v)}</dd>"
                                         for k, v in rows) + "</dl>"


def _warnings(lg: Log, rep: Any) -> str:
    parts = []
    if lg.failure:
        parts.append(f"<p><b>The run failed:</b> {H.esc(lg.failure)}</p>")
    if rep.problems:
        parts.append("<p><b>Incomplete log</b>: everything below is computed from what it "
                     "holds.</p><ul>" + "".join(f"<li>{H.esc(p)}</li>" for p in rep.problems)
                     + "</ul>")
    out = f'<div class="warn" id="warnings">{"".join(parts)}</div>' if parts else ""
    if rep.skipped:  # figures a log does not support: information, not a warning
        out += ('<div class="note" id="not-produced">Not produced: <ul>'
                + "".join(f"<li>{H.esc(s)}</li>" for s in rep.skipped) + "</ul></div>")
    return out


def _plugins(lg: Log) -> str:
    try:
        plugins = lg.plugins
    except Exception:  # noqa: BLE001 - reported by the log's own check
        return "<p class=note>The log's plugin list cannot be read.</p>"
    cols = ["name", "origin", "distribution", "version", "file"]
    t = Table("Plugins the run loaded", cols,
              [[str(p.get(c) or "–") for c in cols] for p in plugins])
    return H.table_html(t, table_id="plugins")


def _replay(lg: Log, trials: dict[int, TrialLog], start_trial: int | None) -> str:
    data = replay_payload(lg, trials)
    data["start_trial"] = start_trial
    data.pop("raw_bytes")
    speeds = "".join(f'<option value="{s}"{" selected" if s == 10 else ""}>{s} it/s</option>'
                     for s in _SPEEDS)
    trails = "".join(f'<option value="{v}">{H.esc(t)}</option>' for v, t in _TRAILS)
    legend = ('<div class="legend"><span><i class="sw" style="background:#0072b2"></i>path'
              '</span><span><i class="sw" style="background:#009e73"></i>beam with echo</span>'
              '<span><i class="sw" style="background:#9a9a9a"></i>no echo (max range)</span>'
              '<span style="color:#d55e00">&#x2715; collision (contact point)</span></div>')
    return f"""
<section id="replay" tabindex="-1" data-ready="0" data-playing="0">
<h2>Replay</h2>
<p class="note">One frame per iteration (1.5 s of robot time). The robot is drawn at the pose
the iteration started from, its beams from the rim to the logged ranges; the bars are the
memberships of the reading in each situation (dominant one dark) with the action its rule
held at that iteration. Space plays/pauses, arrow keys step.</p>
<div class="controls">
<label>Trial <select id="replay-trial"></select></label>
<label>Episode <select id="replay-episode"></select></label>
<button id="replay-play" type="button">Play</button>
<label>Speed <select id="replay-speed">{speeds}</select></label>
<label>Path <select id="replay-trail">{trails}</select></label>
<span>iteration <b id="replay-iter">–</b></span>
<span id="replay-status" class="note">Loading the replay…</span>
</div>
<input id="replay-slider" type="range" min="0" max="0" value="0" step="1"
 aria-label="iteration">
<div class="stage"><div><canvas id="replay-world" width="600" height="600"></canvas>{legend}</div>
<div><pre id="replay-info"></pre><div class="bars" id="replay-bars"></div></div></div>
{H.json_script("replay-data", data)}
</section>"""


def _item(name: str, caption: str, tables: dict[str, Table]) -> str:
    """A figure of the page, or a table with links to its CSV and Markdown files."""
    stem, ext = os.path.splitext(name)
    if ext == ".png":
        return (f'<figure><img src="{H.esc(name)}" alt="{H.esc(caption)}">'
                f"<figcaption>{H.esc(caption)}</figcaption></figure>")
    return (f'{H.table_html(tables[stem])}<p class="note">'
            f'{H.esc(caption.split(" ([CSV]")[0])} · <a href="{H.esc(stem)}.csv">CSV</a> · '
            f'<a href="{H.esc(name)}">Markdown</a></p>')


def write_report_html(rep: Any, lg: Log, trials: dict[int, TrialLog],
                      tables: dict[str, Table]) -> str:
    """Write ``index.html`` into ``rep.out_dir`` and return its path.

    Parameters
    ----------
    rep
        The :class:`~sitframe.analysis.report.AnalysisReport` being written
        (its ``files`` list the figures and tables in order).
    lg
        The log.
    trials
        Every finished trial, read once (the replay embeds them all).
    tables
        Table stem -> :class:`Table`, for the tables in ``rep.files``.
    """
    sections = [(sec, "".join(_item(name, caption, tables) for _s, name, caption in files))
                for sec, files in groupby(rep.files, key=lambda f: f[0])]
    toc = ('<nav class="toc"><a href="#replay">Replay</a>'
           + "".join(f'<a href="#sec{j}">{H.esc(s)}</a>' for j, (s, _) in enumerate(sections))
           + '<a href="#config">Config</a><a href="#plugins-sec">Plugins</a></nav>')
    body = [f"<h1>{H.esc(lg.attrs.get('name', 'sitframe run'))}: analysis of "
            f"<code>{H.esc(os.path.basename(lg.path))}</code></h1>", toc, _meta(lg, rep),
            _warnings(lg, rep)]
    body.append(_replay(lg, trials, rep.trials[0] if rep.trials else None))
    body += [f'<section id="sec{j}"><h2>{H.esc(sec)}</h2>{items}</section>'
             for j, (sec, items) in enumerate(sections)]
    body.append('<section id="config"><h2>Config</h2><details open><summary>The resolved '
                f'config the run used (TOML)</summary><pre>{H.esc(lg.attrs.get("config", ""))}'
                "</pre></details></section>")
    body.append(f'<section id="plugins-sec"><h2>Plugins</h2>{_plugins(lg)}</section>')
    body.append(f'<p class="note">Written by <code>sitframe analyse</code> in '
                f"{rep.seconds:.1f} s. Figures are the PNG files beside this page.</p>")
    path = os.path.join(rep.out_dir, "index.html")
    title = f"{lg.attrs.get('name', 'run')} – sitframe analysis"
    with open(path, "w", encoding="utf-8") as f:
        f.write(H.page(title, "\n".join(body), scripts=(H.template("replay.js"),)))
    return path

