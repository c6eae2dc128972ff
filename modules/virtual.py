"""The robot in virtual time: ``tokenring sim --world W --explore N`` (issue 55).

The same programs ``tokenring up`` downloads into the node processes run on the simulated nodes,
the world simulator runs in the same process on the same virtual clock (each program's
``self.hw`` a hardware client wired straight to it), and ``up``'s own mission
(:class:`~modules.pc.mission.Mission`) drives them through main's PC link. Every wait of
programs, world and mission is the runtime's: the run is deterministic for a seed (frames and
map), and as fast as the machine can compute it.

``--speed K`` is ``up``'s: the world's clock runs K times the ring's, and the wire K times
faster; ``--duration`` is the ring's virtual seconds (``up``'s real ones), so the world lives
K × duration simulated seconds. ``--seed`` is the schedule's and the world's.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import sys
from typing import TYPE_CHECKING, Any

from modules.pc.mission import Mission
from tokenring import SimPlan, UsageError
from tokenring.cli import int_within
from tokenring.runtime import current as current_runtime

if TYPE_CHECKING:
    from pathlib import Path

    from modules.world.sim import Simulator
    from tokenring import Protocol
    from tokenring.sim import SimRing

#: past ``--duration`` the mission may still be fetching the map (``up``'s grace)
GRACE_S = 30.0


def add_sim_options(parser: argparse.ArgumentParser) -> None:
    """The robot's options of ``tokenring sim`` (``up``'s, where they mean the same)."""
    group = parser.add_argument_group(
        "the robot in virtual time",
        "Any of --world, --explore, --actions, --map-out runs the robot's programs and its world in\n"
        "the simulation (without them: the ring alone). --seed is the world's seed too.",
    )
    group.add_argument(
        "--world",
        metavar="NAME|FILE",
        help="bundled room (empty, office, square, slanted) or world file (default office)",
    )
    group.add_argument(
        "--speed",
        default="1",
        metavar="K",
        help="the world's clock runs K times the ring's, 0.01..1000 (default 1), the wire K times "
        "faster too, as with 'up --speed'",
    )
    group.add_argument(
        "--algorithms",
        default="ours",
        metavar="seed|ours|PART=seed,...",
        help="the 2001 robot's algorithms and body, or today's (default), as with 'up --algorithms'",
    )
    group.add_argument("--explore", type=int, choices=(1, 2), help="start Explore 1 (avoid) or 2 (left wall)")
    group.add_argument(
        "--actions",
        metavar="FILE",
        help="have main drive an action file after the compass calibration, as with 'up --actions'",
    )
    group.add_argument(
        "--action-speed",
        type=int_within(1, 100),
        default=50,
        metavar="PCT",
        help="speed of the action file's moves, 1..100 %% of 10 cm/s (default %(default)s)",
    )
    group.add_argument("--map-out", metavar="FILE", help="at the end write the map (.png, .dxf or .json)")


def wanted(args: argparse.Namespace) -> bool:
    """These ``sim`` options ask for the robot (else the ring runs alone)."""
    return bool(args.world or args.explore or args.actions or args.map_out)


def plan_sim(args: argparse.Namespace, protocol: Protocol, programs: Path) -> SimPlan | None:
    """Check the robot's ``sim`` options before anything runs and plan the run (the programs of
    ``programs``, ``<node>.py`` each); None without them."""
    if not wanted(args):
        return None
    from modules.description.roomfile import load_world
    from modules.variants import ENV, all_seed, format_algorithms, parse_algorithms
    from modules.world.__main__ import parse_speed

    if getattr(args, "no_world", False):
        raise UsageError(
            "--no-world runs the ring alone: drop it, or drop --world/--explore/--actions/--map-out"
        )
    if args.explore and args.actions:
        raise UsageError("--explore and --actions both drive the robot: give one of them")
    missing = [name for name in ("main", "motor", "sonar", "compass") if name not in protocol.nodes]
    if missing:
        raise UsageError(f"--world: this protocol has no node {', '.join(missing)} (not the robot's)")
    world = load_world(args.world or "office")
    speed = parse_speed(args.speed)
    choice = parse_algorithms(args.algorithms)
    actions = None
    if args.actions:
        from modules.pc.mission import action_job

        actions = action_job(args.actions, args.action_speed, seed=choice["main"] == "seed")
    if args.map_out:
        from modules.pc.mapfiles import check_out

        check_out(args.map_out, "--map-out", force=getattr(args, "force", False))
    out = sys.stderr if getattr(args, "json", None) == "-" else sys.stdout
    # the LCD's drawing library starts a thread pool when first imported: imported before the
    # simulation, whose tasks are the only threads it may leave behind
    import luma.core.legacy  # noqa: F401

    def scenario(sim: Any, ring: SimRing) -> dict[str, Any]:
        from modules.world.sim import Simulator

        simulator = Simulator(world, seed=args.seed, speed=speed, body=choice["body"])
        return RobotRun(simulator, ring, protocol, out).run(
            programs, duration=args.duration, mode=args.explore, actions=actions, map_out=args.map_out
        )

    return SimPlan(
        speedup=speed,
        profile="arcnet" if all_seed(choice) else None,
        env={ENV: format_algorithms(choice)},
        scenario=scenario,
        report=report,
        failure=lambda facts: facts.get("robot", {}).get("failure"),
    )


class VirtualHost:
    """What a :class:`Mission` asks of ``up``'s launcher, in the simulation: its lines (stamped
    with the virtual clock), whether the run stops, and the request to stop it."""

    ring = "sim"
    session = None

    def __init__(self, out: Any) -> None:
        self.rt = current_runtime()
        self.out = out
        self.stopped = self.rt.event()
        self.stopping = False
        self.lines: list[str] = []

    def say(self, text: str, name: str = "") -> None:
        line = f"{self.rt.monotonic():10.3f} s  {name + ': ' if name else ''}{text}"
        self.lines.append(line)
        print(line, file=self.out, flush=True)

    def request_stop(self) -> None:
        self.stopped.set()


class VirtualMission(Mission):
    """``up``'s mission on main's PC link and the world of this process."""

    def __init__(self, host: VirtualHost, simulator: Simulator, link: Any, **job: Any) -> None:
        super().__init__(host, **job)
        self.simulator = simulator
        self.link = link
        self.fetch_map = True  # map_sha256, with or without --map-out

    def open_link(self) -> Any:
        return self.link

    def world_info(self) -> dict[str, Any] | None:
        return self.simulator.info()

    def end_pose(self, estimate: list[float] | None) -> dict[str, Any] | None:
        from modules.pc.mapfiles import pose_error

        return pose_error(estimate, self.simulator.truth())


class RobotRun:
    """One run of the robot inside the simulation: the world, the programs, the mission."""

    def __init__(self, simulator: Simulator, ring: SimRing, protocol: Protocol, out: Any) -> None:
        from modules.world.devices import attach_devices

        self.simulator = simulator
        self.devices = attach_devices(simulator)
        self.ring = ring
        self.protocol = protocol
        self.host = VirtualHost(out)

    def hardware(self, module: str) -> Any:
        """``module``'s ``self.hw``: its client wired straight to this world (None: no hardware
        here; copro's truth feed serves logs only, the LCD's panel a terminal)."""
        from modules.world.clients import CLIENTS

        if module in CLIENTS:
            return CLIENTS[module].local(self.simulator)
        if module == "gyro":
            from modules.world.gyroclient import GyroHardware

            return GyroHardware.local(self.devices["gyro"])
        if module == "correlator":
            from modules.world.correlatorclient import CorrelatorHardware

            return CorrelatorHardware.local(self.devices["correlator"])
        return None

    def run(
        self,
        programs: Path,
        *,
        duration: float,
        mode: int | None,
        actions: tuple[str, str, int] | None,
        map_out: str | None,
    ) -> dict[str, Any]:
        from tokenring.sim import LocalPcLink, program_errors, start_programs

        rt = current_runtime()
        start = self.simulator.truth()
        started = start_programs(self.ring, programs, self.hardware)
        main = self.ring.nodes[self.protocol.nodes["main"].id]
        link = LocalPcLink(main)
        job = {"mode": mode, "map_out": map_out, "duration": duration, "actions": actions}
        mission = VirtualMission(self.host, self.simulator, link, **job)
        if mode is None and actions is None:  # the world and the programs only: the map at the end
            rt.sleep(duration)
            mission.started = rt.monotonic()
            mission._take_map(mission.link)
        else:
            mission.start()
            if not self.host.stopped.wait(duration + GRACE_S):
                self.host.say("the mission did not end within --duration and its grace: stopped")
            self.host.stopping = True
            mission.thread.join(5.0)
        truth = self.simulator.truth()
        from_start = ((truth["x_mm"] - start["x_mm"]) ** 2 + (truth["y_mm"] - start["y_mm"]) ** 2) ** 0.5
        text = mission.map_text
        failure = mission.error or program_errors(self.ring) or None
        return {
            "map_sha256": hashlib.sha256(text.encode()).hexdigest() if text is not None else "",
            "robot": {
                "world": self.simulator.world.name,
                "speed": self.simulator.clock.speed,
                "world_s": round(self.simulator.clock.now_s(), 6),
                "programs": started,
                "program_errors": program_errors(self.ring),
                "start": [round(start["x_mm"], 3), round(start["y_mm"], 3), round(start["theta_rad"], 6)],
                "truth": [round(truth["x_mm"], 3), round(truth["y_mm"], 3), round(truth["theta_rad"], 6)],
                "from_start_mm": round(from_start, 3),
                "collisions": truth["collisions"],
                "closest_mm": round(truth["closest_mm"], 1) if math.isfinite(truth["closest_mm"]) else None,
                "steps": truth["steps"],
                "map_vectors": 0 if mission.vectors is None else len(mission.vectors),
                "map_score": mission.score,
                "map_out": map_out if mission.map_written else None,
                "failure": None if failure is None else str(failure),
                "lines": self.host.lines,
            },
        }


def report(facts: dict[str, Any]) -> list[str]:
    """The robot's lines under the summary."""
    robot = facts.get("robot", {})
    score = robot.get("map_score") or {}
    lines = [
        f"robot in {robot.get('world')} at speed {robot.get('speed'):g}: {robot.get('world_s', 0):.1f} world s, "
        f"ended at ({robot['truth'][0]:.0f}, {robot['truth'][1]:.0f}) mm, {robot.get('from_start_mm', 0):.0f} mm from its start, "
        f"{robot.get('collisions')} collision(s), closest {robot.get('closest_mm')} mm; map {robot.get('map_vectors')} vectors"
        + (
            f", coverage {score['coverage']:.0%}, precision {score['precision']:.0%}, "
            f"corners {score['corners_closed']}/{score['corners_total']}"
            if score
            else ""
        )
    ]
    if robot.get("program_errors"):
        lines.append(f"program errors: {robot['program_errors']}")
    lines.append(f"map_sha256 {facts.get('map_sha256')}")
    return lines
