"""``tokenring drive``: move the robot by hand through main's PC link (the seed's serial line).

    tokenring drive forward 500 --speed 50      # mm, % of 10 cm/s
    tokenring drive reverse 200
    tokenring drive turn left 90                # degrees
    tokenring drive wheels 40 -40 1500          # left %, right %, ms
    tokenring drive stop                        # ends the move under way; at rest, answers at once
    tokenring drive set-pose 1000 600 90        # x mm, y mm, angle degrees counter-clockwise from +X
    tokenring drive glide 90 -12.5              # RECALC_GLIDE_FACTOR: target degrees, error degrees
    tokenring drive motors off                  # MOTORS_OFF: unpower the drive (Darmstadt key d)
    tokenring drive motors on                   # MOTORS_ON: power it (key e; Darmstadt set: off at boot)
    tokenring drive pose                        # just print the poses

Every command goes into motor's inbox through main, which relays it over the ring; the tool then
follows motor.data until the move is over and prints the dead-reckoned pose next to the true one
(from the world simulator, when one runs). ``motors off|on`` waits until motor.data's state says
so. A move while motor.data says OFF is not sent: the motor would refuse it. Exit 0 when the move
finished, 1 when it ended early (collision, stall, aborted), the motors are off or nobody
answered, 2 on bad input (nothing is sent).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import Any

from tokenring import TokenRingError, UsageError
from tokenring.cli import seconds

HELP = "move the robot by hand (motor commands through main's PC link)"

EXAMPLES = """examples:
  tokenring drive forward 500 --speed 50      # mm, % of 10 cm/s
  tokenring drive turn left 90                # degrees
  tokenring drive wheels 40 -40 1500          # left %, right %, ms
  tokenring drive stop                        # ends the move under way; at rest, answers at once
  tokenring drive set-pose 1000 600 90        # x mm, y mm, angle degrees counter-clockwise from +X
  tokenring drive glide 90 -12.5              # RECALC_GLIDE_FACTOR: target degrees, error degrees
  tokenring drive motors off                  # unpower the drive: moves are refused until ...
  tokenring drive motors on                   # ... it is powered (off at boot with up --sensors darmstadt)
  tokenring drive pose --json                 # just the poses
"""

MOVING, STALLED, COLLISION, OFF = 1, 2, 3, 4
STATE_NAMES = {0: "idle", 1: "moving", 2: "stalled", 3: "collision", 4: "off"}
MOVES = ("MOVE_FORWARD", "MOVE_REVERSE", "TURN_LEFT", "TURN_RIGHT", "SET_WHEEL_SPEEDS")
MOTORS_OFF_MESSAGE = "the motors are off: `tokenring drive motors on` first (in tokenring console: key e)"
#: motor.data samples (distinct stamps) not showing a switch the motor took that mean it made
#: none: up to three can predate the motor carrying it out (the newest before it, the one its
#: loop was making, a SIP sample taken before the command ran)
SWITCH_SAMPLES = 4


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_json_option, add_ring_options, with_examples

    p = sub.add_parser(
        "drive",
        help=HELP,
        description="Send a motor command through main's PC link, follow the move and print the "
        "dead-reckoned and the true pose.",
        **with_examples(EXAMPLES),
    )
    p.add_argument(
        "action",
        choices=("forward", "reverse", "turn", "wheels", "stop", "set-pose", "glide", "motors", "pose"),
        help="what to do",
    )
    p.add_argument("values", nargs="*", help="the action's arguments (see the examples)")
    p.add_argument("--speed", type=float, default=50.0, help="speed in %% of 10 cm/s, 1..100 (default 50)")
    p.add_argument("--timeout", type=seconds, default=120.0, help="real seconds to wait for the move")
    p.add_argument("--no-wait", action="store_true", help="send the command and return at once")
    add_json_option(p)
    add_ring_options(p, listen=False)


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f"{what} must be a number, not {text!r}") from None
    if not math.isfinite(value):
        raise UsageError(f"{what} must be a finite number, not {text!r}")
    return value


def _expect(values: list[str], names: list[str], action: str) -> list[float]:
    if len(values) != len(names):
        raise UsageError(f"drive {action} takes {len(names)} value(s): {' '.join(names) or 'none'}")
    return [_number(v, n) for v, n in zip(values, names, strict=True)]


def build_command(action: str, values: list[str], speed: float) -> tuple[str, dict[str, Any]]:
    """The motor command for an action, checked before anything is sent."""
    if action in ("forward", "reverse", "turn") and not (1 <= speed <= 100 and speed == int(speed)):
        raise UsageError(
            f"--speed {speed:g} must be a whole number of percent within 1..100 (100 % = 10 cm/s)"
        )
    if action in ("forward", "reverse"):
        (distance,) = _expect(values, ["MM"], action)
        if distance < 0:
            raise UsageError(f"distance {distance:g} mm must not be negative (drive reverse goes backwards)")
        if distance > 65535:
            raise UsageError(f"distance {distance:g} mm is more than one move can take (65535)")
        name = "MOVE_FORWARD" if action == "forward" else "MOVE_REVERSE"
        return name, {"distance_mm": round(distance), "speed_pct": int(speed)}
    if action == "turn":
        if len(values) != 2 or values[0] not in ("left", "right"):
            raise UsageError("drive turn takes a side and an angle: turn left|right DEGREES")
        angle = _number(values[1], "angle")
        if not 0 <= angle <= 65535:
            raise UsageError(
                f"angle {angle:g}° must be within 0..65535 (turn the other way for negative angles)"
            )
        name = "TURN_LEFT" if values[0] == "left" else "TURN_RIGHT"
        return name, {"angle_deg": round(angle), "speed_pct": int(speed)}
    if action == "wheels":
        left, right, duration = _expect(values, ["LEFT%", "RIGHT%", "MS"], action)
        if not (-100 <= left <= 100 and -100 <= right <= 100):
            raise UsageError(f"wheel speeds {left:g} % / {right:g} % must be within -100..100 %")
        if not 0 <= duration <= 65535:
            raise UsageError(f"duration {duration:g} ms must be within 0..65535")
        return "SET_WHEEL_SPEEDS", {
            "left_pct": round(left),
            "right_pct": round(right),
            "duration_ms": round(duration),
        }
    if action == "stop":
        _expect(values, [], action)
        return "STOP", {}
    if action == "set-pose":
        x, y, angle = _expect(values, ["X_MM", "Y_MM", "ANGLE_DEG"], action)
        from modules.units import pose_to_wire

        if not (-(2**31) <= x < 2**31 and -(2**31) <= y < 2**31):
            raise UsageError("x and y must fit in 32 bits of millimetres")
        return "SET_GLOBAL_POSITION", pose_to_wire(x, y, math.radians(angle))
    if action == "motors":
        if values not in (["on"], ["off"]):
            raise UsageError("drive motors takes on or off: motors on|off")
        return ("MOTORS_ON" if values == ["on"] else "MOTORS_OFF"), {}
    if action == "glide":
        target, error = _expect(values, ["TARGET_DEG", "ERROR_DEG"], action)
        if target == 0 or not (-327 <= target <= 327 and -327 <= error <= 327):
            raise UsageError("glide takes the target angle (non-zero) and the error, both within ±327°")
        return "RECALC_GLIDE_FACTOR", {"target_deg": round(target), "error_cdeg": round(error * 100)}
    _expect(values, [], action)
    return "", {}


def expected_steps(name: str, args: dict[str, Any], glide_cfactor: int) -> int | None:
    """Half-steps per track the move should take (None: not a counted move)."""
    from modules.sensors.odometry import steps_for_angle, steps_for_distance

    if name in ("MOVE_FORWARD", "MOVE_REVERSE"):
        return steps_for_distance(args["distance_mm"])
    if name in ("TURN_LEFT", "TURN_RIGHT"):
        return steps_for_angle(args["angle_deg"], glide_cfactor / 100.0)
    return None


def run(args: argparse.Namespace) -> int:
    from modules.units import pose_from_wire
    from tokenring.cli import print_json, tap_session
    from tokenring.host import PcLink

    name, command_args = build_command(args.action, args.values, args.speed)
    with tap_session(args) as session:
        link = PcLink(session, args.ring)
        before = _first_read(link)
        status = "sent"
        if name in MOVES and before["state"] == OFF:
            raise TokenRingError(MOTORS_OFF_MESSAGE)  # the motor would refuse it: nothing is sent
        if name:
            reply = link.command("motor", name, **command_args)
            if not reply.get("acknowledged"):
                raise TokenRingError(f"motor did not take {name} (transmitted: {reply.get('transmitted')})")
        after = before
        if name == "STOP" and not args.no_wait:
            after = _until_at_rest(link, args.timeout)  # at rest already: at once
            status = "done"
        elif name in ("MOTORS_ON", "MOTORS_OFF") and not args.no_wait:
            after = _until_switched(link, name == "MOTORS_OFF", args.timeout)
            status = "done"
        elif name and not args.no_wait and name not in ("SET_GLOBAL_POSITION", "RECALC_GLIDE_FACTOR"):
            after = _follow(link, before, name, args.timeout)
            expected = expected_steps(name, command_args, before["glide_cfactor"])
            done = abs(after["steps_left"] - before["steps_left"])
            if after["state"] in (STALLED, COLLISION):
                status = STATE_NAMES[after["state"]]
            elif after["state"] == OFF or (expected is not None and done < expected):
                status = "aborted"  # (OFF: switched off under way)
            else:
                status = "done"
        elif name:
            time.sleep(0.2)
            after = link.read("motor.data")
            status = "done"
        from modules.pc.mapfiles import true_pose

        truth = true_pose(session, args.ring)
    x, y, theta = pose_from_wire(after["x_mm"], after["y_mm"], after["angle_cdeg"])
    result: dict[str, Any] = {
        "command": name or None,
        "args": command_args,
        "status": status if name else "pose",
        "dead_reckoned": {"x_mm": x, "y_mm": y, "angle_deg": math.degrees(theta)},
        "steps": [after["steps_left"], after["steps_right"]],
        "glide_factor": after["glide_cfactor"] / 100.0,
        "motors": "off" if after["state"] == OFF else "on",
        "true": None,
    }
    if truth is not None:
        result["true"] = {
            "x_mm": truth["x_mm"],
            "y_mm": truth["y_mm"],
            "angle_deg": math.degrees(truth["theta_rad"]),
            "collisions": truth["collisions"],
        }
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0 if result["status"] in ("done", "sent", "pose") else 1


def _first_read(link: Any, patience: float = 3.0) -> dict[str, Any]:
    """motor.data from main; a fresh Zenoh session may need a moment before main's PC link is routed."""
    from tokenring import TransportError

    deadline = time.monotonic() + patience
    while True:
        try:
            return link.read("motor.data")
        except TransportError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def _follow(link: Any, before: dict[str, Any], name: str, timeout: float) -> dict[str, Any]:
    """Wait until the motor started and finished this move, showing progress on a terminal."""
    deadline = time.monotonic() + timeout
    started = False
    data = before
    tty = sys.stderr.isatty()
    while time.monotonic() < deadline:
        data = link.read("motor.data")
        started = started or data["move_seq"] != before["move_seq"] or data["state"] == MOVING
        if not started and data["state"] == OFF:  # switched off since the check: refused
            raise TokenRingError(MOTORS_OFF_MESSAGE)
        if started and data["state"] != MOVING:
            break
        if tty and started:
            print(f"\r  {name.lower()}: {data['distance_mm']} mm of track driven", end="", file=sys.stderr)
        time.sleep(0.05)
    else:
        raise TokenRingError(
            f"the move did not finish within {timeout:g} s (motor state {STATE_NAMES.get(data['state'])})"
        )
    if tty:
        print("\r" + " " * 60 + "\r", end="", file=sys.stderr)
    return data


def _until_at_rest(link: Any, timeout: float) -> dict[str, Any]:
    """motor.data once the motor no longer moves: a STOP starts no move to follow (no new
    ``move_seq``), it ends the one under way, if any."""
    deadline = time.monotonic() + timeout
    while True:
        data = link.read("motor.data")
        if data["state"] != MOVING:
            return data
        if time.monotonic() >= deadline:
            raise TokenRingError(f"the robot did not come to rest within {timeout:g} s of the STOP")
        time.sleep(0.05)


def _until_switched(link: Any, off: bool, timeout: float) -> dict[str, Any]:
    """motor.data once its state shows the drive switched ``off`` (or on: any other state)."""
    deadline = time.monotonic() + timeout
    unswitched: set[int] = set()  # stamps of the samples that did not show it
    while True:
        data = link.read("motor.data")
        if (data["state"] == OFF) == off:
            return data
        unswitched.add(data["stamp_ms"])
        state = STATE_NAMES.get(data["state"], data["state"])
        if len(unswitched) >= SWITCH_SAMPLES:
            raise TokenRingError(
                f"the motor took MOTORS_{'OFF' if off else 'ON'} but its state stays {state} "
                "(a motor in seed mode, --algorithms motor=seed, has no switch)"
            )
        if time.monotonic() >= deadline:
            raise TokenRingError(f"motor.data did not change within {timeout:g} s (state {state})")
        time.sleep(0.05)


def _print(result: dict[str, Any]) -> None:
    dr = result["dead_reckoned"]
    if result["command"]:
        print(f"{result['command']} {result['args']}: {result['status']}")
    print(f"dead reckoned  x {dr['x_mm']:8.0f} mm  y {dr['y_mm']:8.0f} mm  angle {dr['angle_deg']:7.2f}°")
    if result["motors"] == "off":
        print("motors         off (`tokenring drive motors on` powers them)")
    truth = result["true"]
    if truth is None:
        print("true pose      (no world simulator answered)")
        return
    print(
        f"true           x {truth['x_mm']:8.0f} mm  y {truth['y_mm']:8.0f} mm  angle {truth['angle_deg']:7.2f}°"
    )
    dx, dy = dr["x_mm"] - truth["x_mm"], dr["y_mm"] - truth["y_mm"]
    da = math.degrees(math.remainder(math.radians(dr["angle_deg"] - truth["angle_deg"]), 2 * math.pi))
    print(
        f"difference     {math.hypot(dx, dy):.0f} mm, {da:+.2f}°   (glide factor {result['glide_factor']:.2f})"
    )
