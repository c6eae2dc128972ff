"""``tokenring up``: launch the whole ring, every node its own process."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from tokenring.errors import UsageError

if TYPE_CHECKING:
    from tokenring.launcher import ServicePlan


def default_programs_dir() -> Path:
    """The ``modules/`` directory holding the eight user programs."""
    import modules

    return Path(modules.__file__).resolve().parent


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cliutil import add_ring_options

    p = sub.add_parser(
        "up",
        help="launch the whole ring (every node its own process)",
        description="Launch every node of protocol.yaml as its own OS process on one Zenoh network "
        "and supervise them until Ctrl-C, SIGTERM or --duration.",
    )
    p.add_argument("--nodes", help="comma-separated subset of nodes (names or IDs); default all")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--bitrate",
        default="2.5M",
        help="emulated ARCNET bitrate, e.g. 2.5M, 10M or max (default %(default)s)",
    )
    p.add_argument(
        "--ack",
        default="adaptive",
        choices=("adaptive", "always", "never"),
        help="pass acknowledgement policy",
    )
    p.add_argument(
        "--programs",
        metavar="DIR",
        help="directory of user programs (default: the modules package)",
    )
    p.add_argument("--no-programs", action="store_true", help="start the nodes with the OS only")
    p.add_argument("--respawn", action="store_true", help="restart nodes that die, like a supervisor")
    world = p.add_argument_group("simulated world")
    world.add_argument(
        "--world",
        default="office",
        metavar="NAME|FILE",
        help="bundled room (empty, office, square, slanted) or world file (default %(default)s)",
    )
    world.add_argument("--speed", default="1", metavar="K", help="simulation speed-up factor (default 1)")
    world.add_argument("--seed", type=int, default=1, help="the world's random seed (default %(default)s)")
    world.add_argument("--no-world", action="store_true", help="start no world simulator (no hardware)")
    mission = p.add_argument_group("exploration")
    mission.add_argument(
        "--explore", type=int, choices=(1, 2), help="start Explore 1 (avoid) or 2 (left wall)"
    )
    mission.add_argument("--map-out", metavar="FILE", help="at the end write the map (.png, .dxf or .json)")
    add_ring_options(p)


def run(args: argparse.Namespace) -> int:
    from tokenring.launcher import Launcher, install_signal_handlers, plans_from_protocol
    from tokenring.protocol import load_protocol
    from tokenring.ring import parse_bitrate

    protocol = load_protocol(args.protocol)
    parse_bitrate(args.bitrate)  # refuse a bad value before anything starts
    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    selection = [s.strip() for s in args.nodes.split(",") if s.strip()] if args.nodes else None
    programs = None if args.no_programs else (args.programs or default_programs_dir())
    if programs is not None and not Path(programs).is_dir():
        raise UsageError(f"--programs {programs}: no such directory")
    plans = plans_from_protocol(protocol, selection, programs)
    services = [] if args.no_world else [world_service(args)]
    launcher = Launcher(
        plans,
        ring=args.ring,
        bitrate=args.bitrate,
        ack_mode=args.ack,
        connect=args.connect or [],
        listen=args.listen or [],
        zenoh_config=args.zenoh_config,
        protocol_path=args.protocol,
        log_level=args.log_level,
        respawn=args.respawn,
        services=services,
    )
    mission = None
    if args.explore or args.map_out:
        from tokenring.commands.explore import Mission
        from tokenring.commands.map import check_out

        if args.map_out:
            check_out(args.map_out)
        mission = Mission(launcher, args.explore, args.map_out, args.duration)
    install_signal_handlers(launcher)
    launcher.start()
    if mission is not None:
        mission.start()  # it follows the exploration, writes the map and stops the launcher
    limit = args.duration
    if mission is not None and limit is not None:
        limit += 30.0  # the mission stops the ring itself; this only caps a stuck map fetch
    code = launcher.run(limit)
    if mission is not None and mission.error and code == 0:
        code = 1
    launcher.say("stopped (interrupted)" if code == 130 else f"stopped (exit code {code})")
    return code


def world_service(args: argparse.Namespace) -> ServicePlan:
    """The world simulator as a launcher service; the world file is checked here, before anything starts."""
    from tokenring.launcher import ServicePlan
    from tokenring.world.__main__ import parse_speed
    from tokenring.world.loader import load_world, resolve_world
    from tokenring.world.service import ready_key

    load_world(args.world)
    parse_speed(args.speed)
    argv = ["tokenring.world", "--ring", "{ring}", "--connect", "{connect}", "--world"]
    argv += [str(resolve_world(args.world).resolve()), "--speed", str(args.speed), "--seed", str(args.seed)]
    argv += ["--log-level", args.log_level]
    if args.zenoh_config:
        argv += ["--zenoh-config", args.zenoh_config]
    return ServicePlan("world", argv, ready_key=ready_key(args.ring))
