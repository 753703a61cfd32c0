"""Animate a logged learning trial: the robot, its sensor rays, situation and command.

From Python::

    from sitframe.analysis import replay
    replay("logs/obstacle-avoidance.h5", trial=0, start=1000, stop=1200, out="t0.gif")

Each frame is one iteration (1.5 s of robot time): the robot disc with its
heading line at the pose the iteration started from, the sensor's rays drawn
from the rim to the logged ranges (a ray at maximum range is drawn dashed:
nothing was seen), the path so far, collisions as crosses at the contact
point, and a text box with the iteration, the dominant situation (largest
membership, with its label and membership), the command (heading change and
speed) and the reward. Only the changing artists are updated per frame
(blitting onto a background drawn once), so a 300-frame GIF takes a few seconds.
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.analysis import results as R
from sitframe.analysis.replay_data import REPLAY_ARRAYS
from sitframe.errors import InputError
from sitframe.sim.world import parse_world
from sitframe.situations.events import count_per_iteration

__all__ = ["DEFAULT_FRAMES", "replay"]

#: Frames drawn when no ``stop`` is given.
DEFAULT_FRAMES = 300
_FONT = 8


def replay(
    log: R.LogLike,
    trial: int,
    out: str | os.PathLike[str],
    *,
    start: int = 0,
    stop: int | None = None,
    fps: int = 8,
    dpi: int = 110,
    trail: int | None = None,
    evaluation: str | None = None,
) -> str:
    """Write an animation (GIF or MP4) of iterations ``[start, stop)`` of a trial.

    Parameters
    ----------
    log
        Log or path.
    trial
        Learning trial index.
    out
        Output file; ``.gif`` (Pillow) or ``.mp4`` (needs ``ffmpeg`` on PATH).
    start, stop
        Iteration window; ``stop`` defaults to ``start + 300`` (clipped to the
        trial length).
    fps
        Frames (iterations) per second of video; 8 fps plays 12x real time.
    dpi
        Resolution.
    trail
        Iterations of path drawn behind the robot (default: all since ``start``).
    evaluation
        World name: animate the trial's frozen-policy evaluation in that world
        (``episodes/eval/<world>/``) instead of its learning run.

    Returns
    -------
    str
        The written path.

    Raises
    ------
    InputError
        Unknown trial, empty window, unsupported suffix, ``.mp4`` without
        ffmpeg, or a trial without the needed arrays.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    from sitframe.analysis.clustering_plots import OKABE_ITO as C  # matplotlib: start-up time
    from sitframe.sim.draw import plot_world  # matplotlib: start-up time

    out = Path(out)
    suffix = _check_output(out, fps)
    lg = R.as_log(log)
    tr = _replay_trial(lg, trial, evaluation)
    what = f"trial {trial}" + ("" if evaluation is None else f", evaluation in {evaluation}")
    pose = np.asarray(tr.arrays["pose"], dtype=np.float64)
    sonar = np.asarray(tr.arrays["reading"], dtype=np.float64)
    u = np.asarray(tr.arrays["memberships"], dtype=np.float64)
    cmd = np.asarray(tr.arrays["command"], dtype=np.float64)
    coll = np.asarray(tr.arrays["collision"], dtype=bool)
    rew_keys = [k for k in tr.arrays if k.startswith("reward/")]
    reward = np.asarray(tr.arrays[rew_keys[0]]) if rew_keys else None
    L = coll.size
    if not 0 <= start < L:
        raise InputError(f"--from must be in [0, {L - 1}] (trial {trial} has {L} iterations), "
                         f"got {start}", key="--from")
    stop = min(L, start + DEFAULT_FRAMES if stop is None else int(stop))
    if stop <= start:
        raise InputError(f"--to must be greater than --from ({start}), got {stop}", key="--to")
    if tr.world not in lg.worlds:
        raise InputError(f"the log does not hold the world '{tr.world}'", file=lg.path,
                         key="worlds")
    world = parse_world(lg.worlds[tr.world], file=f"{lg.path}:worlds/{tr.world}")
    angles = np.deg2rad(R.sensor_angles(lg))
    if angles.size != sonar.shape[1]:
        raise InputError(f"the config's {angles.size} sensor angles do not match the "
                         f"{sonar.shape[1]} logged ranges", file=lg.path, key="sensor")
    max_range = R.sensor_max_range(lg)
    radius = R.robot_radius(lg)
    labels = R.situation_labels(lg)
    if len(labels) != u.shape[1]:
        labels = [f"S{i + 1}" for i in range(u.shape[1])]
    alive = ""  # evolving situations: how many exist at each iteration
    if tr.situations:
        n0 = len(np.asarray(lg.interpreter_state().get("ids", [])))
        counts = (np.full(L, int(tr.situations["count"])) if evaluation is not None else
                  count_per_iteration(tr.situations_part("events"), n0, L))
        alive = "  ({} situations)"
    conv = 0 if evaluation is not None else R.convergence_iteration(tr)
    frozen = "frozen (evaluation)" if evaluation is not None else "frozen (converged)"

    # ---- static background
    x0, y0, x1, y1 = world.bounds
    aspect = (y1 - y0 + 0.6) / (x1 - x0 + 0.6)
    W = 5.0
    fig = Figure(figsize=(W, (W - 0.6) * aspect + 1.7))
    ax = fig.add_subplot()
    plot_world(world, ax=ax, show_trajectories=False, show_start=False, robot_radius=radius)
    ax.set_title("")
    title = what if evaluation is not None else f"{what} in {tr.world}"
    fig.suptitle(f"{lg.attrs.get('name', '')}: {title}", fontsize=_FONT + 1,
                 y=1 - 0.06 / fig.get_figheight(), va="top")
    ax.tick_params(labelsize=_FONT - 1)
    h = fig.get_figheight()
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.95 / h, top=1 - 0.55 / h)

    # ---- animated artists
    path_line, = ax.plot([], [], color=C["blue"], lw=0.8, alpha=0.7, zorder=4)
    body = Circle((0, 0), radius, facecolor="white", edgecolor=C["black"], lw=1.2, zorder=9)
    ax.add_patch(body)
    heading, = ax.plot([], [], color=C["black"], lw=1.4, zorder=10)
    rays = LineCollection([], lw=0.9, zorder=8)
    ax.add_collection(rays)
    hits, = ax.plot([], [], "o", ms=2.2, color=C["bluish_green"], zorder=8)
    crosses, = ax.plot([], [], "x", ms=5, mew=1.3, color=C["vermillion"], zorder=11)
    text = fig.text(0.02, 0.015, "", fontsize=_FONT, family="monospace", va="bottom",
                    ha="left")
    flash = ax.text(0.99, 0.98, "", transform=ax.transAxes, ha="right", va="top",
                    fontsize=_FONT + 1, color=C["vermillion"], weight="bold", zorder=12)
    from matplotlib.lines import Line2D

    fig.legend(handles=[
        Line2D([], [], color=C["bluish_green"], lw=1, marker="o", ms=2.5, label="echo"),
        Line2D([], [], color="0.6", lw=1, ls=(0, (2, 2)), label="no echo (max range)"),
        Line2D([], [], color=C["blue"], lw=1, label="path"),
        Line2D([], [], ls="", marker="x", ms=5, mew=1.3, color=C["vermillion"],
               label="collision")], loc="upper center", fontsize=_FONT - 1, frameon=False,
        ncols=4, bbox_to_anchor=(0.5, 1.0 - 0.32 / fig.get_figheight()), handlelength=1.6,
        columnspacing=1.2)
    cidx = np.flatnonzero(coll[start:stop]) + start
    cpts = R.collision_points(pose, cidx, tr.arrays.get("contact"))
    ray_col_seen, ray_col_free = C["bluish_green"], "0.6"

    def draw(i: int) -> list[Any]:
        x, y, th = pose[i]
        body.center = (x, y)
        heading.set_data([x, x + radius * math.cos(th)], [y, y + radius * math.sin(th)])
        a = th + angles
        rim = np.c_[x + radius * np.cos(a), y + radius * np.sin(a)]
        r = np.minimum(sonar[i], max_range)
        tip = rim + r[:, None] * np.c_[np.cos(a), np.sin(a)]
        rays.set_segments(np.stack([rim, tip], axis=1))
        free = r >= max_range - 1e-9
        rays.set_colors([ray_col_free if f else ray_col_seen for f in free])
        rays.set_linestyles([(0, (2, 2)) if f else "solid" for f in free])
        hits.set_data(tip[~free, 0], tip[~free, 1])
        lo = start if trail is None else max(start, i - trail)
        path_line.set_data(pose[lo:i + 1, 0], pose[lo:i + 1, 1])
        done = cpts[cidx <= i]
        crosses.set_data(done[:, 0], done[:, 1])
        s = int(np.argmax(u[i]))
        phase = ("learning" if conv is None or i < conv else frozen)
        rw = f"   reward {reward[i]:+6.1f}" if reward is not None else ""
        text.set_text(
            f"it. {i:5d}  t = {i * 1.5:7.1f} s   {phase}\n"
            f"situation {labels[s]} (u = {u[i, s]:.2f}){alive and alive.format(counts[i])}\n"
            f"command   heading {cmd[i, 0]:+6.1f} deg, speed {cmd[i, 1]:.2f} m/s{rw}")
        flash.set_text("COLLISION" if coll[i] else "")
        return [path_line, body, heading, rays, hits, crosses, text, flash]

    # ---- blitting: draw the static background once, then only the moving artists
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig.set_dpi(dpi)
    canvas = FigureCanvasAgg(fig)
    animated = draw(start)
    for a in animated:
        a.set_animated(True)
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    # written to a scratch file beside ``out`` and renamed: a failure leaves no half file
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=suffix, dir=out.parent)
        os.close(fd)
    except OSError as exc:
        raise InputError(f"cannot write the animation: {exc.strerror or exc}", file=str(out),
                         key="-o") from None
    tmp = Path(name)
    try:
        frames = _frames(canvas, background, fig, draw, range(start, stop))
        if suffix == ".gif":
            _write_gif(tmp, frames, fps)
        else:
            _write_mp4(tmp, frames, fps, canvas, shown=out)
        os.replace(tmp, out)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise InputError(f"cannot write the animation: {exc.strerror or exc}",
                             file=str(out), key="-o") from None
        raise
    return str(out)


def _frames(canvas: Any, background: Any, fig: Any, draw: Any, its: range) -> Any:
    """Yield each frame as an (h, w, 3) uint8 array."""
    for i in its:
        canvas.restore_region(background)
        for a in draw(i):
            fig.draw_artist(a)
        yield np.asarray(canvas.buffer_rgba())[..., :3].copy()


def _write_gif(out: Path, frames: Any, fps: int) -> None:
    """GIF with one shared palette, built from the first, middle and last frame."""
    from PIL import Image

    arr = list(frames)
    sample = np.concatenate([arr[0], arr[len(arr) // 2], arr[-1]], axis=0)
    palette = Image.fromarray(sample).quantize(colors=160, method=Image.Quantize.MEDIANCUT)
    pal = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in arr]
    pal[0].save(out, save_all=True, append_images=pal[1:], duration=round(1000 / fps), loop=0)


def _write_mp4(out: Path, frames: Any, fps: int, canvas: Any, shown: Path | None = None) -> None:
    """Pipe ``frames`` to ffmpeg writing ``out``; errors name ``shown`` (the user's path)."""
    import subprocess

    w, h = canvas.get_width_height()
    ffmpeg = shutil.which("ffmpeg") or "ffmpeg"
    cmd = [ffmpeg, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
           "-s", f"{w}x{h}", "-r", str(fps), "-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",
           "-c:v", "libx264", "-pix_fmt", "yuv420p", str(out)]
    with subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
        assert proc.stdin is not None
        try:
            for f in frames:
                proc.stdin.write(f.tobytes())
        except BrokenPipeError:
            pass
        proc.stdin.close()
        err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
        if proc.wait() != 0:
            last = (err.strip().splitlines() or [f"exit status {proc.returncode}"])[-1]
            raise InputError(f"ffmpeg failed: {last}", file=str(shown or out), key="-o")


def _check_output(out: Path, fps: int) -> str:
    """The output's suffix (.gif or .mp4, with ffmpeg for .mp4) and a positive ``fps``."""
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise InputError(f"expected an output file ending in .gif or .mp4, got '{out}'",
                         key="-o")
    if suffix == ".mp4" and not shutil.which("ffmpeg"):
        raise InputError("writing .mp4 needs ffmpeg on PATH, which was not found; install "
                         "ffmpeg or write a .gif instead", key="-o")
    if fps < 1:
        raise InputError(f"must be at least 1, got {fps}", key="--fps")
    return suffix


def _replay_trial(lg: Any, trial: int, evaluation: str | None) -> Any:
    """Trial ``trial``, or its evaluation in world ``evaluation`` as a trial, with the arrays
    a replay needs (InputError naming what is missing)."""
    tr = lg.trial(trial)
    what = f"trial {trial}"
    if evaluation is not None:
        episodes = R.evaluation_episodes(tr)
        if evaluation not in episodes:
            raise InputError(f"trial {trial} has no evaluation in world '{evaluation}'; it has "
                             f"{sorted(episodes) or 'none'}", file=lg.path, key="--eval")
        tr = dataclasses.replace(tr, world=evaluation, arrays=episodes[evaluation])
        what = f"trial {trial}, evaluation in {evaluation}"
    need = [k for k in REPLAY_ARRAYS if k not in tr.arrays]
    if need:
        raise InputError(f"{what} lacks the arrays {need}" + (
            " (an older log: its evaluations kept only pose and collision)" if evaluation
            else ""), file=lg.path, key=f"trials/{trial:04d}")
    return tr
