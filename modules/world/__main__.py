"""``python -m modules.world``: run the world simulator for one ring until SIGTERM/SIGINT.

``tokenring up`` starts it as a service before the nodes (``--world``, ``--speed``, ``--seed``).
"""

from __future__ import annotations

import argparse
import logging
import sys

from modules.description import keys as robot_keys
from modules.description.robot import BODIES
from modules.description.roomfile import DEFAULT_WORLD, load_world
from modules.world.service import WorldService
from modules.world.sim import Simulator
from tokenring import TokenRingError, UsageError, keys
from tokenring.cli import int_within, stop_on_signals, wait_for_stop
from tokenring.transport import make_config, open_session

#: the slowest and fastest simulation: below 0.01 the emulated wire (K times the bitrate)
#: crawls and the token hardly moves; above 1000 a simulated step outruns the real machine
MIN_SPEED, MAX_SPEED = 0.01, 1000.0


def parse_speed(text: str) -> float:
    """A speed-up factor within :data:`MIN_SPEED`..:data:`MAX_SPEED` (``20``, ``0.5``)."""
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f"--speed {text!r} is not a number (give {MIN_SPEED:g}..{MAX_SPEED:g})") from None
    if not MIN_SPEED <= value <= MAX_SPEED:  # (NaN fails every comparison: refused too)
        raise UsageError(f"--speed {text}: give a factor within {MIN_SPEED:g}..{MAX_SPEED:g} (1 = real time)")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m modules.world", description="The world simulator of one ring."
    )
    p.add_argument(
        "--world", default=DEFAULT_WORLD, help="bundled room name or world file (default %(default)s)"
    )
    p.add_argument("--speed", default="1", help="simulated seconds per real second (default %(default)s)")
    p.add_argument(
        "--seed", type=int_within(0, 2**32 - 1), default=1, help="random seed (default %(default)s)"
    )
    p.add_argument(
        "--body",
        choices=BODIES,
        default="ours",
        help="the robot's body: today's (side sonars 16 cm apart) or the 2001 robot's (10 cm)",
    )
    p.add_argument("--ring", default=keys.DEFAULT_RING)
    p.add_argument("-e", "--connect", action="append", default=[], metavar="ENDPOINT")
    p.add_argument("-l", "--listen", action="append", default=[], metavar="ENDPOINT")
    p.add_argument("--zenoh-config", metavar="FILE")
    p.add_argument("--duration", type=float, help="stop after this many real seconds")
    p.add_argument("--log-level", default="info", choices=("debug", "info", "warning", "error"))
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="%(levelname)-5s %(message)s")
    stop = stop_on_signals()  # SIGTERM (the launcher) and SIGINT end the service cleanly
    try:
        world = load_world(args.world)
        speed = parse_speed(args.speed)
        ring = keys.check_ring_name(args.ring)
        config = make_config(
            connect=[c for c in args.connect if c], listen=args.listen, config_file=args.zenoh_config
        )
        with open_session(config) as session:
            service = WorldService(
                Simulator(world, seed=args.seed, speed=speed, body=args.body), session, ring
            )
            service.start()
            print(
                f"world {world.name!r} ({len(world.walls)} walls, {len(world.circles)} obstacles), "
                f"speed {speed:g}x, seed {args.seed}, body {args.body}; truth on {robot_keys.world(ring, 'truth')}",
                flush=True,
            )
            try:
                wait_for_stop(stop, args.duration)
            finally:
                service.close()
    except TokenRingError as exc:
        print(f"world: error: {exc}", file=sys.stderr, flush=True)
        return exc.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
