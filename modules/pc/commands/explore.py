"""``tokenring explore 1|2|stop|calibrate|state``: start and stop the robot's exploration via the PC link.

Explore 1 avoids obstacles (turning 90° toward the side with more room), Explore 2 follows the
wall on the robot's left; ``calibrate`` is the seed's 360° calibration run. ``--wait`` follows
the navigator until it finishes (or ``--timeout``), printing its progress.
"""

from __future__ import annotations

import argparse
import time

from tokenring import UsageError
from tokenring.cli import seconds

HELP = "start (1 = avoid, 2 = left wall) or stop the exploration"

EXAMPLES = """examples:
  tokenring explore 2 --wait                  # left-wall following, until it finishes
  tokenring explore 1                         # avoid obstacles; returns at once
  tokenring explore state --json              # the navigator's state
  tokenring explore stop
"""

ACTIONS = ("1", "2", "stop", "calibrate", "state")


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_json_option, add_ring_options, with_examples

    p = sub.add_parser(
        "explore",
        **with_examples(EXAMPLES),
        help=HELP,
        description="Start Explore 1 (avoid) or Explore 2 (left-wall following), the calibration run, "
        "or stop — through main's PC link; 'state' prints the navigator's state.",
    )
    p.add_argument("action", help="1, 2, stop, calibrate or state")
    p.add_argument("--wait", action="store_true", help="follow the navigator until it finishes")
    p.add_argument("--timeout", type=seconds, default=600.0, help="with --wait: give up after S seconds")
    add_json_option(p)
    add_ring_options(p, listen=False)


def run(args: argparse.Namespace) -> int:
    from tokenring.cli import print_json, tap_session

    if args.action not in ACTIONS:
        raise UsageError(f"explore: {args.action!r} is not one of {', '.join(ACTIONS)}")
    if args.timeout <= 0:
        raise UsageError("--timeout must be positive")
    from modules.pc.mission import describe, describe_map, request
    from tokenring.host import open_link

    with tap_session(args) as session:
        link = open_link(session, args.ring)
        state = request(link, args.action)
        if args.wait and args.action in ("1", "2", "calibrate"):
            deadline = time.monotonic() + args.timeout
            last = None
            while state.get("running") and time.monotonic() < deadline:
                time.sleep(1.0)
                state = link.request("state")
                line = describe(state)
                if line != last and not args.json:
                    print(line, flush=True)
                    last = line
        if args.json:
            print_json(state)
        else:
            print(describe(state))
            finished = state.get("finished")
            if finished:
                print(f"finished: {finished.get('why')}{describe_map(finished.get('map'))}")
    return 0
