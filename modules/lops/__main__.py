"""``python -m modules.lops``: LOPS on its stationary PC beside one ring, until SIGTERM/SIGINT.

It joins the ring's Zenoh (``--connect``), takes the world's clock (``hw/clock``) and room
(``world/info``), then measures every 98 simulated ms and puts each packet on
``tokenring/<ring>/robot/lops/packets`` after its WLAN delay. A launcher may run it as a service:
:func:`modules.lops.service.service_argv` and :func:`~modules.lops.service.ready_key`.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import threading
import time
from dataclasses import replace
from typing import Any

from modules.description import keys as robot_keys
from modules.description.room import World
from modules.lops.config import LopsConfigError, for_world, parse_lops_section
from modules.lops.service import LopsService, packets_key
from modules.lops.system import LopsSystem
from modules.world.clients import WORLD_WAIT_S, HardwareClient, HardwareError
from tokenring import TokenRingError, UsageError, keys, read_text
from tokenring.cli import OneLineParser, int_within, seconds, stop_on_signals, wait_for_stop
from tokenring.transport import make_config, open_session, query_one


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog="python -m modules.lops",
        description="LOPS, the Darmstadt external positioning system, beside one ring.",
    )
    p.add_argument("--ring", default=keys.DEFAULT_RING)
    p.add_argument("-e", "--connect", action="append", default=[], metavar="ENDPOINT")
    p.add_argument("-l", "--listen", action="append", default=[], metavar="ENDPOINT")
    p.add_argument("--zenoh-config", metavar="FILE")
    p.add_argument(
        "--seed", type=int_within(0, 2**32 - 1), default=1, help="random seed (default %(default)s)"
    )
    p.add_argument(
        "--config",
        metavar="FILE",
        help="a syncaria/lopscpp configuration file: its [LOPS] section (default: receivers in the room's corners)",
    )
    p.add_argument(
        "--receivers",
        nargs=3,
        metavar="X,Y",
        help="the three receivers' positions in mm (over --config's)",
    )
    p.add_argument("--duration", type=seconds, help="stop after this many real seconds")
    p.add_argument("--log-level", default="info", choices=("debug", "info", "warning", "error"))
    return p


#: a receiver's coordinates, mm: the world's own bound on its numbers
MAX_MM = 1e8


def parse_receivers(texts: list[str]) -> tuple[tuple[float, float], ...]:
    try:
        points = tuple((float(a), float(b)) for a, b in (t.split(",") for t in texts))
    except ValueError:
        raise UsageError(f"--receivers {' '.join(texts)}: give three X,Y pairs in mm") from None
    if not all(math.isfinite(v) and abs(v) <= MAX_MM for point in points for v in point):
        raise UsageError(f"--receivers {' '.join(texts)}: each coordinate a number within +-{MAX_MM:g} mm")
    return points


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="%(levelname)-5s %(message)s")
    stop = stop_on_signals()  # SIGTERM (the launcher) and SIGINT end the service cleanly
    try:
        ring = keys.check_ring_name(args.ring)
        receivers = parse_receivers(args.receivers) if args.receivers else None
        config_text = read_text(args.config, "LOPS configuration file") if args.config else None
        config = make_config(
            connect=[c for c in args.connect if c], listen=args.listen, config_file=args.zenoh_config
        )
        with open_session(config) as session:
            clock = HardwareClient(session, ring).clock  # waits for a world that is still starting
            world = World.geometry_from_dict(_query(session, robot_keys.world(ring, "info")))
            lops = parse_lops_section(config_text) if config_text is not None else for_world(world)
            if receivers is not None:
                lops = replace(lops, receivers=receivers)
            state_key = robot_keys.world(ring, "state")

            def truth() -> tuple[float, float, float] | None:
                try:
                    state = query_one(session, state_key, timeout=1.0)
                except TokenRingError:
                    return None
                return float(state["t_ms"]), float(state["x_mm"]), float(state["y_mm"])

            service = LopsService(LopsSystem(world, lops, seed=args.seed), session, ring, clock, truth)
            print(
                f"lops: receivers {lops.receivers} mm in {world.name!r}, trigger {lops.trigger_period_ms:g} ms, "
                f"seed {args.seed}; packets on {packets_key(ring)}",
                flush=True,
            )
            runner = threading.Thread(target=service.run, name="lops", daemon=True)
            runner.start()
            try:
                wait_for_stop(stop, args.duration)  # the main thread: where a signal wakes
            finally:
                service.stop.set()
                runner.join(timeout=5.0)
            print(f"lops: stopped after {service.counts}", flush=True)
    except (OSError, LopsConfigError) as exc:
        print(f"lops: error: {exc}", file=sys.stderr, flush=True)
        return 2
    except TokenRingError as exc:
        print(f"lops: error: {exc}", file=sys.stderr, flush=True)
        return exc.exit_code
    return 0


def _query(session: Any, key: str) -> Any:
    """One answer from the world, waiting for one still starting."""
    deadline = time.monotonic() + WORLD_WAIT_S
    while True:
        try:
            return query_one(session, key, timeout=1.0)
        except TokenRingError:
            if time.monotonic() > deadline:
                raise HardwareError(
                    f"no world answered {key} (start python -m modules.world first)"
                ) from None
            time.sleep(0.1)


if __name__ == "__main__":
    sys.exit(main())
