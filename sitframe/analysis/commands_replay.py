"""Animate a logged trial: ``sitframe replay LOG --trial K [--eval W] [--from I --to J] -o FILE``.

Without ``--eval`` the learning trial is shown; with ``--eval W`` the frozen
rule base's evaluation run in world ``W`` (logs written since evaluations
keep their sonar, memberships and commands).

The robot (disc and heading) moves through its world with its sonar rays
(drawn from the rim to the logged ranges; dashed = nothing within range), the
path so far, collisions marked, and as text the dominant situation, the
command and the reward. ``.gif`` is written with Pillow; ``.mp4`` needs
ffmpeg on PATH.
"""

from __future__ import annotations

import argparse

# start-up time: this module is imported whenever the command line builds its parser
# (``sitframe --help`` and every command), so what only one command needs is imported
# inside the function that needs it.

HELP = "animate a logged trial (robot, sonar rays, situation, command) as GIF or MP4"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``replay`` options to ``parser``."""
    parser.add_argument("log", help="HDF5 log written by `sitframe run`")
    parser.add_argument("--trial", type=int, default=0, metavar="K",
                        help="learning trial to animate (default 0)")
    parser.add_argument("--eval", dest="eval_world", default=None, metavar="W",
                        help="animate trial K's frozen-policy evaluation in world W instead")
    parser.add_argument("--from", dest="start", type=int, default=0, metavar="I",
                        help="first iteration (default 0)")
    parser.add_argument("--to", dest="stop", type=int, default=None, metavar="J",
                        help="stop before this iteration (default I + 300)")
    parser.add_argument("-o", "--output", required=True, metavar="FILE",
                        help="output animation, .gif or .mp4 (mp4 needs ffmpeg)")
    parser.add_argument("--fps", type=int, default=8,
                        help="iterations shown per second (default 8 = 12x real time)")
    parser.add_argument("--dpi", type=int, default=110, help="resolution (default 110)")


def main(args: argparse.Namespace) -> int:
    """Write the animation and print its path."""
    from sitframe.analysis.replay import replay
    from sitframe.errors import InputError
    from sitframe.logs import open_log

    if args.dpi < 1:
        raise InputError(f"must be at least 1, got {args.dpi}", key="--dpi")
    log = open_log(args.log)
    log.check()  # damaged contents: one line before any drawing
    print(replay(log, args.trial, args.output, start=args.start, stop=args.stop, fps=args.fps,
                 dpi=args.dpi, evaluation=args.eval_world))
    return 0
