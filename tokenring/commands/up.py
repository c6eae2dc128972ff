"""``tokenring up``: launch the whole ring, every node its own process."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

from tokenring.errors import UsageError

if TYPE_CHECKING:
    from tokenring.launcher import Launcher, ServicePlan


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
    p.add_argument(
        "--no-download",
        action="store_true",
        help="give each node its program file at start instead of booting bare and loading over the ring",
    )
    p.add_argument(
        "--store",
        metavar="DIR",
        help="root of the nodes' program stores (default $TOKENRING_STORE or ~/.local/state/tokenring)",
    )
    p.add_argument("--respawn", action="store_true", help="restart nodes that die, like a supervisor")
    p.add_argument(
        "--profile",
        choices=("arcnet",),
        help="emulate the seed robot's hardware timing on top of the wire: the 8051s' per-visit work and "
        "channel copies, the sonar's interrupt lock (tokenring/profile.py; needs a bitrate, not max)",
    )
    p.add_argument(
        "--router",
        action="store_true",
        help="this launcher is its host's Zenoh router (needs --listen); its nodes are clients of it. "
        "For rings across hosts: only router-to-router links cross between hosts",
    )
    p.add_argument(
        "--boot-wave",
        type=int,
        metavar="N",
        help="at most N nodes booting at a time; a bigger ring starts in waves, a new node as each "
        "booting one comes live (default: 8 per core)",
    )
    world = p.add_argument_group("simulated world")
    world.add_argument(
        "--world",
        default="office",
        metavar="NAME|FILE",
        help="bundled room (empty, office, square, slanted) or world file (default %(default)s)",
    )
    world.add_argument(
        "--speed",
        default="1",
        metavar="K",
        help="simulation speed-up factor (default 1); the emulated wire runs K times faster too",
    )
    world.add_argument("--seed", type=int, default=1, help="the world's random seed (default %(default)s)")
    world.add_argument("--no-world", action="store_true", help="start no world simulator (no hardware)")
    mission = p.add_argument_group("exploration")
    mission.add_argument(
        "--explore", type=int, choices=(1, 2), help="start Explore 1 (avoid) or 2 (left wall)"
    )
    mission.add_argument("--map-out", metavar="FILE", help="at the end write the map (.png, .dxf or .json)")
    mission.add_argument(
        "--actions",
        metavar="FILE",
        help="have main drive an action file (seed §6.7: e, s MM, r DEG, v L R MS, c R SPEED MS, #) "
        "after the compass calibration, then stop the ring",
    )
    mission.add_argument(
        "--action-speed", type=int, default=50, metavar="PCT", help="speed of the action file's moves"
    )
    mission.add_argument(
        "--localizer",
        metavar="YAML",
        help="copro's sync + EKF configuration, e.g. config/localization.yaml (the Darmstadt "
        "setup: compass + walls of the wall file, data and error logs); default: exploration "
        "mode without logs",
    )
    add_ring_options(p)


def run(args: argparse.Namespace) -> int:
    from tokenring.launcher import BOOT_CONCURRENCY, Launcher, install_signal_handlers, plans_from_protocol
    from tokenring.protocol import load_protocol
    from tokenring.ring import format_bitrate, parse_bitrate

    protocol = load_protocol(args.protocol)
    bitrate = parse_bitrate(args.bitrate)  # refuse a bad value before anything starts
    try:
        speed = float(args.speed)
    except ValueError:
        raise UsageError(f"--speed {args.speed!r}: expected a number such as 1, 5 or 20") from None
    if not 0 < speed <= 1000:
        raise UsageError(f"--speed {speed} must be in 0..1000")
    # everything emulated runs K times faster with --speed K, the wire included: a round of
    # the ring must stay as short in simulated time as it is on the real robot
    wire = args.bitrate if bitrate is None or args.no_world else format_bitrate(bitrate * speed)
    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    if args.profile and bitrate is None:
        raise UsageError(
            f"--profile {args.profile} emulates hardware timing: give a bitrate such as 2.5M, not max"
        )
    selection = [s.strip() for s in args.nodes.split(",") if s.strip()] if args.nodes else None
    programs = None if args.no_programs else (args.programs or default_programs_dir())
    if programs is not None and not Path(programs).is_dir():
        raise UsageError(f"--programs {programs}: no such directory")
    main_id = protocol.nodes["main"].id if "main" in protocol.nodes else None
    download = programs is not None and not args.no_download
    plans = plans_from_protocol(protocol, selection, None if download else programs)
    if download and main_id not in {p.node_id for p in plans}:
        download = False  # no main, no PC link: the programs start from their files
        plans = plans_from_protocol(protocol, selection, programs)
    services = [] if args.no_world else [world_service(args)]
    launcher = Launcher(
        plans,
        ring=args.ring,
        bitrate=wire,
        ack_mode=args.ack,
        connect=args.connect or [],
        listen=args.listen or [],
        zenoh_config=args.zenoh_config,
        protocol_path=args.protocol,
        log_level=args.log_level,
        respawn=args.respawn,
        router=args.router,
        profile=args.profile,
        services=services,
        extra_node_args=["--store", args.store] if args.store else [],
        boot_concurrency=BOOT_CONCURRENCY if args.boot_wave is None else args.boot_wave,
    )
    if args.localizer:
        from modules.common.locconfig import load_config

        load_config(args.localizer)  # a bad file is refused (file:line, key) before anything starts
        os.environ["TOKENRING_LOCALIZER_CONFIG"] = str(Path(args.localizer).resolve())
    mission = None
    if args.explore and args.actions:
        raise UsageError("--explore and --actions both drive the robot: give one of them")
    if args.explore or args.map_out or args.actions:
        from tokenring.commands.explore import Mission
        from tokenring.commands.map import check_out

        if args.map_out:
            check_out(args.map_out)
        actions = None
        if args.actions:
            from modules.common.actions import load_actions

            load_actions(args.actions)  # a bad file is refused (file:line) before anything starts
            actions = (
                Path(args.actions).name,
                Path(args.actions).read_text(encoding="utf-8"),
                args.action_speed,
            )
        mission = Mission(launcher, args.explore, args.map_out, args.duration, actions=actions)
    install_signal_handlers(launcher)
    launcher.start()
    boot_ok = True
    if download:
        boot_ok = boot_load(launcher, Path(programs), {p.node_id for p in plans})
    if mission is not None:
        mission.start()  # it follows the exploration, writes the map and stops the launcher
    limit = args.duration
    if mission is not None and limit is not None:
        limit += 30.0  # the mission stops the ring itself; this only caps a stuck map fetch
    code = launcher.run(limit)
    if mission is not None and mission.error and code == 0:
        code = 1
    if not boot_ok and code == 0:
        code = 1
    launcher.say("stopped (interrupted)" if code == 130 else f"stopped (exit code {code})")
    launcher.flush_output()
    return code


def boot_load(launcher: Launcher, programs: Path, ids: set[int], wait: float = 30.0) -> bool:
    """The seed's boot: the nodes run their OS only; scan them, load every program that is newer
    than the node's (``load -i``: a restarted ring finds them in its stores and sends nothing)
    through main's PC link, then ARCNET_START_SYSTEM. False if a node failed (named in the output)."""
    from tokenring.commands.explore import open_link
    from tokenring.errors import TokenRingError
    from tokenring.loader import Loader, run_load

    launcher.booting = True
    try:
        assert launcher.session is not None
        link = open_link(launcher.session, launcher.ring, wait=wait)
        loader = Loader(
            link,
            progress=False,
            say=lambda text: launcher.say(text, name="load"),
            cancelled=launcher._stop.is_set,
        )
        result = run_load(
            loader, mode="incremental", programs_dir=programs, start=True, expect=ids, wait=wait
        )
        return not result["failed"]
    except TokenRingError as exc:
        launcher.say(f"loading the programs failed: {exc}", name="load")
        return False
    finally:
        launcher.booting = False


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
