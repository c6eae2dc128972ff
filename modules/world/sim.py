"""The world simulator's state and physics, without any transport: one instance per ring.

:class:`Simulator` answers the hardware requests (the handlers below are what
``tokenring/<ring>/hw/...`` queries reach) and produces the ground truth. It is deterministic
given its seed and the sequence of requests: each subsystem draws from its own random stream.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from modules.description.robot import (
    DEFAULT_MOTOR_CURRENT_MA,
    SONAR_COUNT,
    SONAR_SLOT_MS,
    sonar_mounts,
    sonar_world_pose,
)
from modules.description.room import Pose, World
from modules.world import echo
from modules.world.battery import (
    ELECTRONICS_CURRENT_A,
    MOTOR_PACK_A_PER_MOTOR_A,
    Battery,
)
from modules.world.clock import SimClock
from modules.world.magnetics import CompassBridges
from modules.world.physics import TrackedRobot
from tokenring.runtime import current as current_runtime

ADC_COUNTS = 1023  # the charger's 10-bit ADC
ELECTRONICS_FULL_SCALE_V = 15.0  # voltage dividers in front of the ADC
MOTORS_FULL_SCALE_V = 45.0
CURRENT_FULL_SCALE_A = 5.0


class HardwareRequestError(ValueError):
    """A hardware request the simulated device cannot take (bad field or value)."""


def _int(
    request: dict[str, Any],
    key: str,
    default: int | None = None,
    lo: int | None = None,
    hi: int | None = None,
) -> int:
    value = request.get(key, default)
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or (isinstance(value, float) and not math.isfinite(value))
    ):
        raise HardwareRequestError(f"{key} must be a number, not {value!r}")
    value = int(value)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise HardwareRequestError(f"{key} must be within {lo}..{hi}, not {value}")
    return value


def _float(request: dict[str, Any], key: str, default: float | None = None) -> float:
    value = request.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise HardwareRequestError(f"{key} must be a number, not {value!r}")
    return float(value)


#: a velocity older than this (no batch of steps since) no longer carries the robot on (pose_at)
VELOCITY_HOLD_MS = 250.0


class Simulator:
    """The robot's hardware and its room."""

    def __init__(
        self,
        world: World,
        seed: int = 0,
        speed: float = 1.0,
        clock: SimClock | None = None,
        body: str = "ours",
    ) -> None:
        self.world = world
        self.seed = seed
        self.body = body
        self.mounts = sonar_mounts(body)  # where the chosen body carries its sonar pairs
        self.clock = clock or SimClock(speed)
        streams = np.random.SeedSequence(seed).spawn(4)
        self.robot = TrackedRobot(world, np.random.default_rng(streams[0]))
        self.sonar_rng = np.random.default_rng(streams[1])
        self.bridges = CompassBridges(world, np.random.default_rng(streams[2]))
        self.adc_rng = np.random.default_rng(streams[3])
        self.electronics = Battery("electronics", 1, 24.0, world.batteries.electronics_soc)
        self.motors = Battery("motors", 3, 72.0, world.batteries.motors_soc)
        self.relay_on = True
        self.relay_reason = ""
        self.motor_pack_a = 0.0
        self.energised = False
        self.drive_power = True  # the motor's MOTORS_OFF/ON (hw/motor/power); on at power-on
        self.last_ms = self.clock.now_ms()
        self.steps_total = [0, 0]
        self.steps_unpowered = [0, 0]  # half-steps that arrived without power: not made
        self.lock = current_runtime().rlock()
        # how the robot moves until the motor's next batch of steps (mm/ms, mm/ms, rad/ms) and
        # since when: a sonar sweep pings its pairs one after another while it drives on
        self.velocity = (0.0, 0.0, 0.0)
        self.velocity_since_ms = 0.0

    # -- time and power -------------------------------------------------------------------------
    def advance(self, now_ms: float | None = None) -> float:
        """Bring the batteries up to ``now_ms`` (default: the clock); returns the time used."""
        now = self.clock.now_ms() if now_ms is None else now_ms
        with self.lock:
            dt = max(0.0, now - self.last_ms) / 1000.0
            self.last_ms = max(self.last_ms, now)
            self.electronics.current_a = ELECTRONICS_CURRENT_A if self.powered else 0.0
            self.electronics.drain(self.electronics.current_a, dt)
            self.motors.current_a = self.motor_pack_a if self.energised else 0.0
            self.motors.drain(self.motors.current_a, dt)
        return now

    @property
    def powered(self) -> bool:
        """The relays hold and the electronics battery is not flat."""
        return self.relay_on and self.electronics.soc > 0.0

    def pose_at(self, at_ms: float, now_ms: float | None = None) -> Pose:
        """Where the robot is at ``at_ms``: a batch of steps moves it to where the motor had got
        to when it sent them, and until the next batch it drives on at that batch's velocity (the
        motor steps on meanwhile; the next batch brings those steps). Without this, every sonar
        ping, compass reading and truth sample between two batches saw the robot where the last
        batch left it — at speed 20 tens to hundreds of simulated ms behind its stamp. ``now_ms``
        (default ``at_ms``): when asked; no batch for ``VELOCITY_HOLD_MS`` by then, the motors off
        or no power: it stands."""
        pose = self.robot.pose
        asked = at_ms if now_ms is None else now_ms
        if not (self.energised and self.powered) or asked - self.velocity_since_ms > VELOCITY_HOLD_MS:
            return pose
        ahead = max(0.0, at_ms - self.velocity_since_ms)
        vx, vy, omega = self.velocity
        return Pose(pose.x + vx * ahead, pose.y + vy * ahead, pose.theta + omega * ahead)

    def motors_running(self, _now_ms: float | None = None) -> bool:
        """The motor driver is on: the coils carry current (and make their running field)."""
        return self.energised

    # -- hardware requests ----------------------------------------------------------------------
    def clock_info(self, _: dict[str, Any] | None = None) -> dict[str, Any]:
        return {
            "sim_ms": self.clock.now_ms(),
            "speed": self.clock.speed,
            "seed": self.seed,
            "world": self.world.name,
        }

    def motor_steps(self, request: dict[str, Any]) -> dict[str, Any]:
        """``hw/motor/steps``: a batch of half-steps both motors made since the last batch."""
        left = _int(request, "left", 0, -100000, 100000)
        right = _int(request, "right", 0, -100000, 100000)
        rate = _float(request, "rate_hz", 1.0)
        move = _int(request, "move", 0)
        current_ma = _int(request, "current_ma", DEFAULT_MOTOR_CURRENT_MA, 0, 5100)
        energised = bool(request.get("energised", True))
        if rate <= 0:
            raise HardwareRequestError(f"rate_hz must be positive, not {rate}")
        with self.lock:
            now = self.advance()
            reply: dict[str, Any] = {
                "stamp_ms": now,
                "moved_mm": 0.0,
                "turned_rad": 0.0,
                "blocked": False,
                "stalled": False,
                "power": True,
                "drive": True,
            }
            if not (self.powered and self.drive_power) or self.motors.soc <= 0.0:
                self.energised = False  # pose_at: a robot without energised motors stands
                self.velocity = (0.0, 0.0, 0.0)
                self.steps_unpowered[0] += left
                self.steps_unpowered[1] += right
                reply.update(power=False, drive=self.drive_power)
                return reply
            self.steps_total[0] += left
            self.steps_total[1] += right
            before = self.robot.pose
            result = self.robot.apply_steps(left, right, rate, move)
            after = self.robot.pose
            duration_ms = 1000.0 * max(abs(left), abs(right)) / rate
            if energised and duration_ms > 0 and not (result.blocked or result.stalled):
                self.velocity = (
                    (after.x - before.x) / duration_ms,
                    (after.y - before.y) / duration_ms,
                    math.remainder(after.theta - before.theta, 2 * math.pi) / duration_ms,
                )
            else:
                self.velocity = (0.0, 0.0, 0.0)
            self.velocity_since_ms = now
            self.energised = energised
            self.motor_pack_a = MOTOR_PACK_A_PER_MOTOR_A * current_ma / 1000.0
            self.motors.current_a = self.motor_pack_a if energised else 0.0
            reply.update(
                moved_mm=result.distance,
                turned_rad=result.rotation,
                blocked=result.blocked,
                stalled=result.stalled,
            )
            return reply

    def motor_power(self, request: dict[str, Any]) -> dict[str, Any]:
        """``hw/motor/power``: switch the drive's power on or off (the motor's MOTORS_ON/OFF).
        Off, the coils carry no current and steps that arrive are not made (counted)."""
        on = request.get("on")
        if not isinstance(on, bool):
            raise HardwareRequestError(f"on must be true or false, not {on!r}")
        with self.lock:
            self.advance()
            self.drive_power = on
            if not on:
                self.energised = False
                self.velocity = (0.0, 0.0, 0.0)
            return {"drive": self.drive_power}

    def motor_start(self, _: dict[str, Any] | None = None) -> dict[str, Any]:
        """``hw/motor/start``: where the operator placed the robot at power-on (the world file's start
        pose, the robot's marked start spot) — the only pose a module is ever given."""
        start = self.world.start
        return {"x_mm": start.x, "y_mm": start.y, "theta_rad": start.theta}

    def sonar_ping(self, request: dict[str, Any]) -> dict[str, Any]:
        """``hw/sonar/ping``: ping the listed pairs one after another, ``slot_ms`` apart."""
        sensors = request.get("sensors", [0])
        if (
            not isinstance(sensors, list)
            or not sensors
            or not all(isinstance(s, int) and 0 <= s < SONAR_COUNT for s in sensors)
        ):
            raise HardwareRequestError(
                f"sensors must be a list of pair numbers 0..{SONAR_COUNT - 1}, not {sensors!r}"
            )
        ping = _int(request, "ping_samples", echo.DEFAULT_PING_SAMPLES, 1, 500)
        slot = _float(request, "slot_ms", SONAR_SLOT_MS)
        with self.lock:
            now = self.advance()
            envelopes, stamps = [], []
            for i, sensor in enumerate(sensors):
                # pair i is pinged i slots later, from where the driving robot is by then
                pose = self.pose_at(now + i * slot, now)
                sx, sy, direction = sonar_world_pose(pose.x, pose.y, pose.theta, sensor, self.mounts)
                if self.powered:
                    samples = echo.envelope(self.world, sx, sy, direction, self.sonar_rng, ping)
                else:
                    samples = np.zeros(echo.SONAR_SAMPLES, dtype=np.uint8)
                envelopes.append(samples.tobytes())
                stamps.append(now + i * slot)
            return {"envelopes": envelopes, "stamps_ms": stamps, "sample_us": echo.SONAR_SAMPLE_US}

    def compass_measure(self, request: dict[str, Any]) -> dict[str, Any]:
        """``hw/compass/measure``: for each setting (flip, compensation), ``samples`` ADC readings
        of both bridges, one per millisecond, the settings one after another."""
        settings = request.get("settings")
        if not isinstance(settings, list) or not settings:
            raise HardwareRequestError("settings must be a non-empty list of {flip, comp_ut}")
        samples = _int(request, "samples", 20, 1, 1000)
        with self.lock:
            now = self.advance()
            pose = self.pose_at(now)
            running = self.motors_running(now)
            out = []
            for i, setting in enumerate(settings):
                if not isinstance(setting, dict):
                    raise HardwareRequestError(f"setting {i} must be a mapping, not {setting!r}")
                flip = _int(setting, "flip", 1, -1, 1)
                comp = setting.get("comp_ut", [0.0, 0.0])
                if not isinstance(comp, list) or len(comp) != 2:
                    raise HardwareRequestError("comp_ut must be [bridge 0, bridge 1] in µT")
                comp_ut = (_float({"c": comp[0]}, "c"), _float({"c": comp[1]}, "c"))
                if not self.powered:
                    out.append([[0] * samples, [0] * samples])
                    continue
                adc = self.bridges.measure(
                    pose.x, pose.y, pose.theta, running, flip, comp_ut, samples, now + i * samples
                )
                out.append(adc.tolist())
            return {"adc": out, "stamp_ms": now, "sample_ms": 1.0}

    def charger_adc(self, _: dict[str, Any] | None = None) -> dict[str, Any]:
        """``hw/charger/adc``: the charger's 10-bit ADC on both battery dividers and the current shunt."""
        with self.lock:
            now = self.advance()
            current = self.electronics.current_a + self.motors.current_a

            def counts(value: float, full_scale: float) -> int:
                raw = value / full_scale * ADC_COUNTS + self.adc_rng.normal(0.0, 0.5)
                return int(min(ADC_COUNTS, max(0, round(raw))))

            return {
                "electronics": counts(self.electronics.voltage(), ELECTRONICS_FULL_SCALE_V),
                "motors": counts(self.motors.voltage(), MOTORS_FULL_SCALE_V),
                "current": counts(current, CURRENT_FULL_SCALE_A),
                "full_scale": {
                    "counts": ADC_COUNTS,
                    "electronics_v": ELECTRONICS_FULL_SCALE_V,
                    "motors_v": MOTORS_FULL_SCALE_V,
                    "current_a": CURRENT_FULL_SCALE_A,
                },
                "relay": self.relay_on,
                "stamp_ms": now,
            }

    def charger_relay(self, request: dict[str, Any]) -> dict[str, Any]:
        """``hw/charger/relay``: hold or drop the power relays (dropping them cuts all hardware)."""
        on = request.get("on")
        if not isinstance(on, bool):
            raise HardwareRequestError(f"on must be true or false, not {on!r}")
        with self.lock:
            self.advance()
            self.relay_on = on
            self.relay_reason = str(request.get("reason", ""))
            return {"relay": self.relay_on}

    HANDLERS: ClassVar[dict[str, str]] = {
        "clock": "clock_info",
        "motor/steps": "motor_steps",
        "motor/start": "motor_start",
        "motor/power": "motor_power",
        "sonar/ping": "sonar_ping",
        "compass/measure": "compass_measure",
        "charger/adc": "charger_adc",
        "charger/relay": "charger_relay",
    }

    def handle(self, what: str, request: dict[str, Any]) -> Any:
        """Dispatch a hardware request by its key tail (``motor/steps``)."""
        name = self.HANDLERS.get(what)
        if name is None:
            raise HardwareRequestError(f"no hardware at hw/{what} (have: {', '.join(sorted(self.HANDLERS))})")
        return getattr(self, name)(request)

    # -- ground truth and the hand of god (tests, tools) ----------------------------------------
    def info(self) -> dict[str, Any]:
        """The room (:meth:`World.to_dict`) with the seed, speed and body (``world/info``)."""
        return {**self.world.to_dict(), "seed": self.seed, "speed": self.clock.speed, "body": self.body}

    def truth(self) -> dict[str, Any]:
        """Ground truth: for logs and scoring only, never for the modules."""
        with self.lock:
            now = self.advance()
            pose = self.pose_at(now)
            return {
                "stamp_ms": int(now),
                "t_ms": now,
                "x_mm": pose.x,
                "y_mm": pose.y,
                "theta_rad": pose.theta,
                "x": pose.x,
                "y": pose.y,
                "theta": pose.theta,
                "heading_rad": self.world.heading(pose.theta),
                "moving": self.energised,
                "collisions": self.robot.collisions,
                "closest_mm": self.robot.closest_mm,
                "stalls": self.robot.stalls,
                "steps": list(self.steps_total),
                "drive": self.drive_power,
                "steps_unpowered": list(self.steps_unpowered),
                "glide_factor": self.robot.glide,
                "relay": self.relay_on,
                "electronics": self.electronics.as_dict(),
                "motors": self.motors.as_dict(),
                "deep_discharge": self.electronics.deep_discharged() or self.motors.deep_discharged(),
                "world": self.world.name,
            }

    def set_pose(self, request: dict[str, Any]) -> dict[str, Any]:
        """Put the robot somewhere else (tests); refuses a pose inside a wall."""
        x, y = _float(request, "x_mm"), _float(request, "y_mm")
        theta = _float(request, "theta_rad", self.robot.pose.theta)
        if self.world.clearance(x, y) < self.world.robot_radius:
            raise HardwareRequestError(f"({x:g}, {y:g}) is inside a wall or obstacle")
        with self.lock:
            self.robot.pose = Pose(x, y, theta)
        return self.truth()

    def set_batteries(self, request: dict[str, Any]) -> dict[str, Any]:
        """Set the state of charge of either battery (tests)."""
        with self.lock:
            self.advance()
            for name, battery in (("electronics", self.electronics), ("motors", self.motors)):
                if name in request:
                    soc = _float(request, name)
                    if not 0.0 <= soc <= 1.0:
                        raise HardwareRequestError(f"{name} state of charge must be within 0..1, not {soc}")
                    battery.soc = soc
        return self.truth()
