"""How the robot plugs into the ring: its PC verbs, its programs, its world and hardware.

Registered in ``pyproject.toml`` under the entry point group ``tokenring.extensions``; the ring
(:mod:`tokenring.extensions`) asks it, and only it, for everything robot-specific:

* the verbs ``drive``, ``explore``, ``map``, ``score``, ``lcd``, ``log``, ``replay``, ``analyze``
  (:mod:`modules.pc.commands`);
* the programs: this package's ``<node>.py`` files;
* ``tokenring up``'s world (``--world``, ``--speed``, ``--seed``, ``--no-world``) and its jobs
  (``--explore``, ``--map-out``, ``--actions``, ``--localizer``), all checked before anything
  starts;
* ``tokenring sim``'s robot: the world, the programs and ``up``'s mission in virtual time
  (``--world``, ``--explore``, ``--actions``, ``--map-out``: :mod:`modules.virtual`);
* each program's hardware client (:mod:`modules.world.hardware`);
* the LCD node's OS menu before the programs start (:mod:`modules.display.boot_menu`);
* its topics in a live feed (:mod:`modules.pc.feed`);
* its web view's panels, buttons and keys, and ``tokenring web --action`` (:mod:`modules.pc.web`).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from tokenring import Extension, UpPlan, UsageError
from tokenring.cli import int_within, seconds

if TYPE_CHECKING:
    from pathlib import Path
    from types import ModuleType

    import zenoh

    from tokenring import Protocol, ResidentProgram, SimPlan, WebAction, WebKeys, WebPanel
    from tokenring.host import Launcher, ServicePlan
    from tokenring.observe import FeedSource


#: a world's random seed (numpy's generators take 0..2**32-1 and fail on a negative one)
MAX_SEED = 2**32 - 1

#: ``up --sensors``: the optional nodes of protocol.yaml each sensor set adds to the Hamburg
#: robot's eight (LOPS joins "darmstadt" as a service beside the ring); see :func:`sensor_nodes`
SENSOR_SETS: dict[str, tuple[str, ...]] = {"hamburg": (), "darmstadt": ("gyro", "correlator")}


def programs_dir() -> Path:
    """Where the programs are: this package's directory."""
    from pathlib import Path

    return Path(__file__).resolve().parent


def __getattr__(name: str) -> Any:
    """``PROGRAMS_DIR`` (:func:`programs_dir`), made when first asked for: listing the robot's
    verbs (``tokenring --help``) imports no pathlib."""
    if name == "PROGRAMS_DIR":
        return programs_dir()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class RobotExtension(Extension):
    """The 2001 robot on the ring."""

    name = "robot"

    def commands(self) -> list[ModuleType]:
        """The verbs of :mod:`modules.pc.commands`, a module each (listed by their ``HELP``)."""
        from modules.pc import commands
        from tokenring.cli import verb_modules

        return verb_modules(commands)

    def programs_dir(self) -> Path:
        return programs_dir()

    def add_up_options(self, parser: argparse.ArgumentParser) -> None:
        world = parser.add_argument_group("simulated world (the robot's hardware)")
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
            help="simulation speed-up factor, 0.01..1000 (default 1); the emulated wire runs K times faster too",
        )
        world.add_argument(
            "--seed",
            type=int_within(0, MAX_SEED),
            default=1,
            help=f"the world's random seed, 0..{MAX_SEED} (default %(default)s)",
        )
        world.add_argument("--no-world", action="store_true", help="start no world simulator (no hardware)")
        world.add_argument(
            "--sensors",
            choices=sorted(SENSOR_SETS),
            default="hamburg",
            help="the robot's sensors: the Hamburg robot's eight modules (default) or with the "
            "Darmstadt sensors as well (darmstadt: the gyroscope, node gyro; the floor correlator, "
            "node correlator, except on the seed's body, --algorithms seed or body=seed, whose was "
            "defective; LOPS, the positioning system beside the ring; the motor sends its odometry "
            "as the Pioneer's SIPs, every 100 ms of its clock, and its drive is off at boot, as "
            "the Pioneer's: tokenring drive motors on, or an action file's e, before a move)",
        )
        world.add_argument(
            "--algorithms",
            default="ours",
            metavar="seed|ours|PART=seed,...",
            help="the 2001 robot's algorithms and body ('seed': every module as it was, side sonars "
            "10 cm apart, at the seed's wire pace --profile arcnet unless --bitrate is given) or "
            "today's ('ours', default); per part, e.g. 'sonar=seed' or 'seed,copro=ours' (parts: "
            "sonar, copro, main, motor, body)",
        )
        parser.add_argument_group(
            "the LCD",
            "From boot until the programs run (with --no-start: until you start them) the LCD shows\n"
            "its OS V2.0 Main Menu: 1 Start Robbi starts the programs (tokenring lcd --keys 1),\n"
            "2 Components lists every node with its program date (tokenring lcd --keys 2).",
        )
        mission = parser.add_argument_group("exploration")
        mission.add_argument(
            "--explore", type=int, choices=(1, 2), help="start Explore 1 (avoid) or 2 (left wall)"
        )
        mission.add_argument(
            "--map-out", metavar="FILE", help="at the end write the map (.png, .dxf or .json)"
        )
        mission.add_argument(
            "--actions",
            metavar="FILE",
            help="have main drive an action file (seed §6.7: e, s MM, r DEG, v L R MS, c R SPEED MS, #) "
            "after the compass calibration, then stop the ring",
        )
        mission.add_argument(
            "--action-speed",
            type=int_within(1, 100),
            default=50,
            metavar="PCT",
            help="speed of the action file's moves, 1..100 %% of 10 cm/s (default %(default)s)",
        )
        mission.add_argument(
            "--console",
            action="store_true",
            help="open the operator's screen (tokenring console) in this terminal once the programs "
            "run; its x or q stops the ring (the launcher's lines go to a file meanwhile)",
        )
        mission.add_argument(
            "--localizer",
            metavar="YAML",
            help="copro's sync + EKF configuration, e.g. config/localization.yaml (the Darmstadt "
            "setup: compass + walls of the wall file, data and error logs), or a bundled one by name: "
            "early-ekf (the seed's early filter: odometry + gyroscope, untuned; with --sensors "
            "darmstadt); default: exploration mode without logs",
        )

    def up_nodes(self, args: argparse.Namespace, protocol: Protocol) -> list[str]:
        check_sensors(args, protocol)
        return list(sensor_nodes(args))

    def plan_up(self, args: argparse.Namespace, protocol: Protocol) -> UpPlan:
        from modules.variants import ENV, all_seed, format_algorithms, parse_algorithms
        from modules.world.__main__ import parse_speed

        plan = UpPlan()
        check_sensors(args, protocol)
        choice = parse_algorithms(args.algorithms)  # a bad value is refused before anything starts
        plan.env[ENV] = format_algorithms(choice)
        if all_seed(choice):
            plan.profile = "arcnet"
        speed = parse_speed(args.speed)
        receivers: list[list[float]] | None = None
        if not args.no_world:
            plan.services.append(world_service(args, choice["body"]))
            plan.speedup = speed
            if args.sensors == "darmstadt":  # LOPS beside the ring, measuring in that world
                receivers = [list(r) for r in lops_receivers(args.world)]
                plan.services.append(lops_service(args, receivers))
                # copro's Localizer knows them as the seed's robot did, from the same [LOPS] values
                plan.env["TOKENRING_LOPS_RECEIVERS"] = json.dumps(receivers)
        if args.sensors != "hamburg":  # copro's Localizer takes the set's sensors too
            plan.env["TOKENRING_SENSORS"] = args.sensors
        if args.sensors == "darmstadt":  # the Pioneer's SIPs (an explicit setting wins, 0 = off)
            import os

            from modules.description.robot import MOTOR_POWER_ENV, MOTOR_SIP_ENV, SIP_PERIOD_MS
            from modules.motor import powered_at_boot

            plan.env[MOTOR_SIP_ENV] = os.environ.get(MOTOR_SIP_ENV, str(SIP_PERIOD_MS))
            # its drive off at boot until MOTORS_ON (the key e; §6.7); an explicit setting wins
            plan.env[MOTOR_POWER_ENV] = os.environ.get(MOTOR_POWER_ENV, "off")
            try:
                powered_at_boot(plan.env)
            except ValueError as exc:
                raise UsageError(str(exc)) from None
        if args.localizer:
            from modules.localization.config import config_path, load_config, seed_notes, sensor_set_layer

            # a bad file is refused (file:line, key) before anything starts, over what copro lays
            # beneath it; a seed file's values that do not apply here are said once, on stderr
            with seed_notes():
                load_config(args.localizer, under=sensor_set_layer(args.sensors, receivers))
            plan.env["TOKENRING_LOCALIZER_CONFIG"] = str(config_path(args.localizer).resolve())
        if args.explore and args.actions:
            raise UsageError("--explore and --actions both drive the robot: give one of them")
        plan.start_hint = lcd_start_hint
        incomplete = incomplete_watch()
        plan.on_started = incomplete.start
        plan.failure = incomplete.failure
        if args.console:
            if getattr(args, "no_start", False):
                raise UsageError("--console drives the running programs: drop --no-start")
            from modules.pc.console.launch import with_console

            with_console(plan, args)
        if not (args.explore or args.map_out or args.actions):
            return plan
        if getattr(args, "no_start", False):
            raise UsageError(
                "--no-start leaves the programs waiting at the LCD's menu: --explore, --actions and "
                "--map-out need them running (drop --no-start, or start them and run 'tokenring explore')"
            )
        if args.map_out:
            from modules.pc.mapfiles import check_out

            check_out(args.map_out, "--map-out", force=getattr(args, "force", False))
        actions = None
        if args.actions:
            from modules.pc.mission import action_job

            actions = action_job(args.actions, args.action_speed, seed=choice["main"] == "seed")
        missions: list[Any] = []

        started, failed = plan.on_started, plan.failure

        def start_mission(launcher: Launcher) -> None:
            from modules.pc.mission import Mission

            if started is not None:
                started(launcher)
            mission = Mission(launcher, args.explore, args.map_out, args.duration, actions=actions)
            missions.append(mission)
            mission.start()  # it follows the exploration, writes the map and stops the launcher

        def failure() -> str | None:
            return (missions[0].failure() if missions else None) or (failed() if failed else None)

        plan.on_started = start_mission
        plan.failure = failure
        plan.grace_s = 30.0  # the mission stops the ring itself; this only caps a stuck map fetch
        return plan

    def add_sim_options(self, parser: argparse.ArgumentParser) -> None:
        """``tokenring sim``'s robot: its world, programs and mission in virtual time
        (:mod:`modules.virtual`)."""
        from modules.virtual import add_sim_options

        add_sim_options(parser)

    def plan_sim(self, args: argparse.Namespace, protocol: Protocol) -> SimPlan | None:
        from modules.virtual import plan_sim

        return plan_sim(args, protocol, programs_dir())

    def add_load_options(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument(
            "-u", "--upload", metavar="FILE", help="upload the map into FILE (.dxf, .png, .json)"
        )
        parser.add_argument("--timeout", type=seconds, default=60.0, help="seconds to wait for the map (-u)")
        parser.add_argument("--force", action="store_true", help="replace an existing -u FILE")

    def check_load(self, args: argparse.Namespace) -> None:
        if args.upload:
            from modules.pc.mapfiles import check_out

            check_out(args.upload, "--upload", force=args.force)

    def after_load(
        self, args: argparse.Namespace, session: zenoh.Session, say: Callable[[str], None]
    ) -> dict[str, Any]:
        if not args.upload:
            return {}
        from modules.pc.mapfiles import fetch_map, live_world, truth_from_info, write_map

        vectors = fetch_map(session, args.ring, args.timeout)
        info = live_world(session, args.ring)
        world, truth = truth_from_info(info) if info else (None, None)
        write_map(vectors, args.upload, truth, world, option="--upload")
        say(f"map: {len(vectors)} vectors written to {args.upload}")
        return {"upload": {"file": args.upload, "vectors": len(vectors)}}

    def open_hardware(self, module: str, session: zenoh.Session, ring: str) -> Any | None:
        if module == "copro":  # the world's truth and the WLAN receiver of LOPS's packets
            from modules.lops.receiver import CoproHardware

            return CoproHardware(session, ring)
        from modules.world.hardware import open_hardware

        return open_hardware(module, session, ring)

    def resident_program(self, module: str) -> type[ResidentProgram] | None:
        """The LCD node's OS V2.0 Main Menu, shown from boot until the programs run."""
        if module != "lcd":
            return None
        from modules.display.boot_menu import LcdOs

        return LcdOs

    def feed_sources(self, protocol: Protocol, ring: str) -> list[FeedSource]:
        """The robot's topics in a live feed: poses, sonar, map, walls, LCD (:mod:`modules.pc.feed`)."""
        from modules.pc.feed import robot_feed_sources

        return robot_feed_sources(protocol, ring)

    def web_panels(self) -> list[WebPanel]:
        """The room, the map, the poses and the LCD in the web view (:mod:`modules.pc.web`)."""
        from modules.pc.web import panels

        return panels()

    def web_actions(self) -> list[WebAction]:
        """Explore 1, Explore 2 and stop as buttons of the web view."""
        from modules.pc.web import actions

        return actions()

    def add_web_options(self, parser: argparse.ArgumentParser) -> None:
        """``tokenring web --action FILE``: the action files of the keys a, b, c."""
        from modules.pc.web.keys import add_options

        add_options(parser)

    def web_keys(self, args: argparse.Namespace) -> WebKeys:
        """The seed's keys (table 8.2) on the web page, carried out as ``tokenring console`` does."""
        from modules.pc.web.keys import web_keys

        return web_keys(args)


def check_sensors(args: argparse.Namespace, protocol: Protocol) -> None:
    """A set whose nodes this protocol lacks is refused; a ``--nodes`` given with ``--sensors``
    must name the set's nodes (or the sensors would silently not run)."""
    wanted = sensor_nodes(args)
    missing = [name for name in wanted if name not in protocol.nodes]
    if missing:
        raise UsageError(f"--sensors {args.sensors}: this protocol has no node {', '.join(missing)}")
    nodes = getattr(args, "nodes", None)
    if not wanted or nodes is None:
        return
    given = set()
    for item in (s.strip() for s in nodes.split(",") if s.strip()):
        try:
            given.add(protocol.node(int(item) if item.isdigit() else item).name)
        except Exception:
            return  # up names the bad --nodes item itself
    left_out = [name for name in wanted if name not in given]
    if left_out:
        raise UsageError(
            f"--sensors {args.sensors} adds {', '.join(wanted)}, which --nodes leaves out: name "
            f"{', '.join(left_out)} in --nodes too, or drop --nodes"
        )


def sensor_nodes(args: argparse.Namespace) -> tuple[str, ...]:
    """The nodes ``--sensors`` adds: its set's, less the floor correlator on the seed's body
    (``--algorithms seed`` or ``body=seed``): seed 000's was at the manufacturer and never ran
    (§3.3); the world gives that body a defective one."""
    from modules.variants import parse_algorithms

    nodes = SENSOR_SETS[getattr(args, "sensors", "hamburg")]
    if "correlator" in nodes and parse_algorithms(getattr(args, "algorithms", "ours"))["body"] == "seed":
        return tuple(name for name in nodes if name != "correlator")
    return nodes


def incomplete_watch() -> Any:
    """What names a module whose run is not whole (copro's logs cut short by a full disk) and
    makes ``up`` exit 1: :class:`modules.pc.mission.IncompleteWatch`."""
    from modules.pc.mission import IncompleteWatch

    return IncompleteWatch()


def lcd_start_hint(launcher: Launcher) -> str | None:
    """``up --no-start``: how to start the programs from the LCD's OS menu (if the lcd node runs)."""
    if not any(plan.name == "lcd" for plan in launcher.plans):
        return None
    command = " ".join(["tokenring", "lcd", *launcher.tool_options(), "--keys", "1"])
    return f"the LCD waits at its OS V2.0 Main Menu: 1 (Start Robbi) starts the programs: {command}"


def lops_receivers(world: str) -> tuple[tuple[float, float], ...]:
    """Where LOPS's three receivers stand in the room ``up`` runs (its default: three corners)."""
    from modules.description.roomfile import load_world
    from modules.lops.config import default_receivers

    return default_receivers(load_world(world))


def lops_service(args: argparse.Namespace, receivers: list[list[float]]) -> ServicePlan:
    """LOPS, the Darmstadt positioning system, as a launcher service started after the world
    (it measures in that world): its packets reach the robot beside the token, never in it. A
    new LOPS after a death only starts its filter afresh, as the seed's lopscpp did: restartable."""
    from modules.lops.service import ready_key, service_argv
    from tokenring.host import ServicePlan

    argv = service_argv(seed=args.seed, log_level=args.log_level, zenoh_config=args.zenoh_config)
    argv += ["--receivers", *(f"{x:g},{y:g}" for x, y in receivers)]
    return ServicePlan("lops", argv, ready_key=ready_key(args.ring), restart=True)


def world_service(args: argparse.Namespace, body: str = "ours") -> ServicePlan:
    """The world simulator as a launcher service; the world file is checked here, before anything starts."""
    from modules.description.roomfile import load_world, resolve_world
    from modules.world.__main__ import parse_speed
    from modules.world.service import ready_key
    from tokenring.host import ServicePlan

    load_world(args.world)
    parse_speed(args.speed)
    argv = ["modules.world", "--ring", "{ring}", "--connect", "{connect}", "--world"]
    argv += [str(resolve_world(args.world).resolve()), "--speed", str(args.speed), "--seed", str(args.seed)]
    argv += ["--body", body]
    argv += ["--log-level", args.log_level]
    if args.zenoh_config:
        argv += ["--zenoh-config", args.zenoh_config]
    return ServicePlan("world", argv, ready_key=ready_key(args.ring))
