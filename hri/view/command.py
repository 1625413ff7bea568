"""The `hri view` command line: its flags, wired into `hri` by hri/cli.py without importing the server."""

from __future__ import annotations

import argparse

from common.settings import add_option
from hri.view import DEFAULT_MAX_FPS

VIEW_EXAMPLES = """\
examples:
  hri view                                     # live page of the local stack; prints its URL
  hri view --connect tcp/robot.local:7447 --host 0.0.0.0 --port 8080
  hri view session.mcap                        # a recording, with play/pause and a time slider
  hri view --snapshot out.png                  # the annotated frame of the first camera, as a PNG
  hri view session.mcap --snapshot out.png --at 1790000012.5 --cam table
"""


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", nargs="?", default=None, help="an .mcap from `hri record` to open instead of the bus")
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to serve the page on (default 127.0.0.1; 0.0.0.0 for other machines)",
    )
    add_option(p, "--port", 8080, "port (0 picks a free one)", at_least=0, at_most=65535)
    add_option(p, "--max-fps", DEFAULT_MAX_FPS, "frames per second per camera sent to the page", above=0, metavar="FPS")
    p.add_argument(
        "--snapshot",
        metavar="OUT.png",
        default=None,
        help="write the annotated frame of a camera to this PNG and exit (no server)",
    )
    p.add_argument(
        "--at",
        type=float,
        default=None,
        metavar="STAMP",
        help="with --snapshot and a recording: the session as of this source stamp (UNIX seconds; "
        "a value below 1e9 counts seconds from the recording's start). Default: its end",
    )
    p.add_argument("--cam", default=None, help="with --snapshot: the camera (default the first with a frame)")
    add_option(
        p,
        "--wait",
        2.0,
        "with --snapshot on the live bus: seconds to watch after the first frame",
        at_least=0,
        metavar="S",
    )
    add_option(
        p,
        "--timeout",
        30.0,
        "with --snapshot on the live bus: give up after S seconds without a frame",
        above=0,
        metavar="S",
    )
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    from hri.view.server import cmd_view as run  # aiohttp, OpenCV: only when `hri view` runs

    return run(args)
