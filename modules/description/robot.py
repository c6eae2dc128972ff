"""The robot's body: what the modules know about their hardware (and the simulator builds).

Robot frame: x forward, y to the left, angles in radians counter-clockwise from forward; the
robot's reference point is the middle between the tracks (it turns on the spot about it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# -- drive (seed §3.3.1 and §4.3.3) --------------------------------------------------------------
WHEEL_CIRCUMFERENCE_MM = 216.77  # drive wheel with the 69 mm track
HALF_STEPS_PER_TURN = 400  # half-step mode, 0.9° per half-step
STEP_MM = WHEEL_CIRCUMFERENCE_MM / HALF_STEPS_PER_TURN  # 0.5419 mm per half-step
MAX_SPEED_MM_S = 100.0  # 100 % = 10 cm/s, the start-stop limit (no ramps)
MAX_STEP_RATE_HZ = MAX_SPEED_MM_S / STEP_MM  # 184.5 half-steps per second at 100 %
DEFAULT_GLIDE_FACTOR = 6.5  # half-steps per degree of turn on tiles
DEFAULT_MOTOR_CURRENT_MA = 1000  # per motor, set through the 8-bit DAC (20 mA per count)
MOTOR_TICK_MS = 20.0  # the motor module issues a batch of steps every 20 simulated ms
#: the Darmstadt Pioneer's SIP (server information packet) period: its microcontroller sent the
#: position data every 100 ms of its own clock (seed 000, §2.3, §3.4, §5.4)
SIP_PERIOD_MS = 100
#: the motor's setting for a SIP stream: sample and publish the counters only at the grid times
#: k·period of its clock (ms; unset or 0: every loop tick, the Hamburg motor)
MOTOR_SIP_ENV = "TOKENRING_MOTOR_SIP_MS"
#: the motor's setting for the drive's power at boot: "on" (unset: the Hamburg drive, which has
#: no switch) or "off" (the Darmstadt Pioneer answered drive commands only after "Motoren an",
#: the operator's key e: seed 000 §6.7, §8.2)
MOTOR_POWER_ENV = "TOKENRING_MOTOR_POWER"
ROBOT_RADIUS_MM = 190.0  # the collision circle the simulator uses

# -- compass (seed §3.3.3) -------------------------------------------------------------------------
#: the two KMZ51 bridges' sensitive axes: bridge 0 along the robot's forward axis, bridge 1 to its
#: left. With the horizontal field at heading psi (from north, clockwise) the bridges see
#: H cos(psi) and H sin(psi).
COMPASS_AXES = (0.0, math.pi / 2)

# -- sonar (seed §4.3.2) ---------------------------------------------------------------------------
SONAR_COUNT = 8
SONAR_BEAM_RAD = math.radians(30.0)  # full width at half sensitivity
SONAR_RANGE_MM = 1500.0  # useful range
SONAR_NO_CONTACT = 255  # the seed's "no contact" byte
SONAR_SAMPLES = 510  # one envelope: 510 samples ...
SONAR_SAMPLE_US = 20.0  # ... every 20 µs (three-fold oversampling of the 60 µs per cm)
SPEED_OF_SOUND_M_S = 330.0
SONAR_SLOT_MS = 15.0  # one pair's measurement slot: eight make the 120 ms sweep (8.3 Hz)


@dataclass(frozen=True)
class SonarMount:
    """Where a transmitter/receiver pair sits on the robot and where it looks."""

    index: int
    name: str
    x: float  # mm, robot frame
    y: float
    angle: float  # radians CCW from forward


#: the transducers' faces sit on the body's outline, a hair inside it (their holders' rim): this
#: far from the reference point, in whole millimetres (188 mm on the 190 mm collision circle)
SONAR_OUTLINE_MM = 188.0
SONAR_DIAGONAL_MM = 133.0  # the ±45° pairs, forward and to the side: 188.1 mm out
SIDE_PAIR_X_MM = 80.0  # each side's two pairs are 160 mm apart, symmetric about the reference point
SIDE_PAIR_Y_MM = 170.0  # ... and 187.9 mm out
#: the 2001 robot's side pairs were about 10 cm apart: seed 001 §4.3.4 gives the smallest object
#: its edge follower maps as "etwa 10cm", the span both side sensors of a side must see
SEED_SIDE_PAIR_X_MM = 50.0
SEED_SIDE_PAIR_Y_MM = 181.0  # ... 187.8 mm out, on the same outline
#: the bodies a ring can run: today's (side pairs 160 mm apart) and the 2001 robot's (100 mm)
BODIES = ("ours", "seed")


def sonar_mounts(body: str = "ours") -> tuple[SonarMount, ...]:
    """The eight pairs in sweep order on ``body``: three to the front (+45°, 0°, -45°), two on
    each side, one rear. The bodies differ only in how far apart each side's two pairs sit.

    Every transducer sits on the body's outline (2 mm inside the collision circle), so an object
    the body touches is 0-3 cm from the nearest pair facing it: what the seed calls ALERT (seed
    §4.3.2 "ALERT 0cm bis 4cm"; §4.3.6: the pilot aborts any move when a sensor reads under
    4 cm) is what a sonar reads just before the robot touches. The seed's pairs are separate
    transmitters and receivers, so that they measure while sending (§3.3.2: "Dies ermöglicht eine
    Messung auch während des Sendens"): no blind zone, a touched wall reads 0-3 cm. Mounted
    40-70 mm inside the body, a touched wall read 4-7 cm and ALERT was out of reach."""
    if body not in BODIES:
        raise ValueError(f"no robot body {body!r} (bodies: {', '.join(BODIES)})")
    side_x, side_y = (
        (SEED_SIDE_PAIR_X_MM, SEED_SIDE_PAIR_Y_MM) if body == "seed" else (SIDE_PAIR_X_MM, SIDE_PAIR_Y_MM)
    )
    return (
        SonarMount(0, "front-left", SONAR_DIAGONAL_MM, SONAR_DIAGONAL_MM, math.radians(45)),
        SonarMount(1, "front", SONAR_OUTLINE_MM, 0.0, 0.0),
        SonarMount(2, "front-right", SONAR_DIAGONAL_MM, -SONAR_DIAGONAL_MM, math.radians(-45)),
        SonarMount(3, "right-front", side_x, -side_y, math.radians(-90)),
        SonarMount(4, "right-rear", -side_x, -side_y, math.radians(-90)),
        SonarMount(5, "rear", -SONAR_OUTLINE_MM, 0.0, math.pi),
        SonarMount(6, "left-rear", -side_x, side_y, math.radians(90)),
        SonarMount(7, "left-front", side_x, side_y, math.radians(90)),
    )


#: today's body, the default everywhere a body is not chosen
SONAR_MOUNTS = sonar_mounts("ours")
SONAR_BY_NAME = {m.name: m.index for m in SONAR_MOUNTS}
FRONT_LEFT, FRONT, FRONT_RIGHT, RIGHT_FRONT, RIGHT_REAR, REAR, LEFT_REAR, LEFT_FRONT = range(8)


def sonar_world_pose(
    x: float, y: float, theta: float, index: int, mounts: tuple[SonarMount, ...] = SONAR_MOUNTS
) -> tuple[float, float, float]:
    """Where sonar pair ``index`` sits and looks in world coordinates, for a robot at (x, y, theta)."""
    m = mounts[index]
    c, s = math.cos(theta), math.sin(theta)
    return (x + c * m.x - s * m.y, y + s * m.x + c * m.y, theta + m.angle)
