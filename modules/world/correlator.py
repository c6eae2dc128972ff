"""The floor correlator (Darmstadt seed 000 §3.3, Bratos 2002) and its hardware request.

Two light sensors sit one behind the other on the robot's axis and see the floor's brightness;
the floor passes under both, so the trailing one sees what the leading one saw, later. The
correlator finds that time offset τ and gives the translation as the spacing over τ (table 3.1:
a translation increment, at a variable rate of more than 40 ms a sample). Its faults are the
seed's three, made from the geometry:

* **turning reads too large**: off the pivot, the floor under the pair moves on circles round the
  instantaneous centre of rotation. A patch leaving the leading sensor is nearest the trailing
  one after turning through the angle the two sensors make at that centre, Δφ; the correlator
  reads L·|ω|/Δφ, which is |v|·(1 + x₁x₂/R²) on an arc of radius R — too large, whichever way
  it turns, as §3.3 says (exactly: :func:`correlated_speed`).
* **on the spot no correlation at all**: the two sensors run on circles of different radii; when
  these lie further apart than the light spot is wide (:data:`SPOT_MM`) the signals share
  nothing, and the correlator still reports its best peak: a bogus translation of the size the
  floor moves under it, in a random direction.
* **wrong direction**: now and then a reading's sign is wrong, more often in dynamic drives
  (§3.3: "besonders bei dynamischen Fahrten des öfteren").

Bratos 2002 (the sensor's thesis) is not among the seeds: every number below not marked seed is
ours, with its reason. Deterministic from the world's seed (a random stream of its own).

The world serves it at ``hw/correlator/read`` (:class:`CorrelatorDevice`,
:data:`modules.world.devices`): ``{}`` → ``{increments_um: [...], stamps_ms: [...], lost, power,
defective}``, every sample since the previous read (at most :data:`MAX_SAMPLES`, the oldest
dropped and counted in ``lost``). On the seed's body (``--body seed``) the correlator is
defective, as seed 000's was (at the manufacturer, §3.3): no samples, ``defective`` true. What
each sample really was stays in the model (:attr:`CorrelatorDevice.truth`), for tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from modules.world.sim import HardwareRequestError

SAMPLE_MIN_MS = 40.0  # seed table 3.1: "variabel (>40ms)"
#: ours: each period is 40 ms plus up to this (uniform); the seed says only "variable"
SAMPLE_JITTER_MS = 20.0
#: ours: the two light sensors' spacing along the axis (the correlator's baseline)
SPACING_MM = 25.0
#: ours: the light spot's width; tracks further apart than this share no floor texture
SPOT_MM = 8.0
#: ours: the pair's midpoint on the robot's axis, behind the pivot (seed: only "not at the pivot");
#: on the axis, so every turn reads too large (§3.3), not one direction too small
MOUNT_X_MM = -120.0
NOISE_REL = 0.02  # ours: a correlated reading's relative noise (the peak's width), per sample
FLIP_P = 0.01  # ours: a steady drive's readings in the wrong direction, per sample
FLIP_P_DYNAMIC = 0.15  # ours: the same while accelerating (§3.3: "des öfteren" in dynamic drives)
DYNAMIC_MM_S2 = 200.0  # ours: a change of speed between two samples faster than this is dynamic
#: ours: a bogus reading (no correlation) is the floor's speed under the pair times U(0.5, 1.5)
BOGUS_SPREAD = 0.5
STILL_MM_S = 0.5  # ours: the floor slower than this under the sensors gives no signal: 0
MAX_SAMPLES = 256  # samples a read returns at most (over 10 s): older ones are lost
#: the stream of the world's seed the correlator draws from (the simulator's are 0..3, the gyro 16)
SEED_STREAM = 17


@dataclass(frozen=True)
class Mount:
    """Where the two sensors sit on the robot's axis (mm, robot frame, + forward of the pivot)."""

    x_mm: float = MOUNT_X_MM
    spacing_mm: float = SPACING_MM
    spot_mm: float = SPOT_MM

    @property
    def rear_mm(self) -> float:
        return self.x_mm - self.spacing_mm / 2

    @property
    def front_mm(self) -> float:
        return self.x_mm + self.spacing_mm / 2


def correlated_speed(vx: float, vy: float, omega: float, mount: Mount) -> tuple[float, float]:
    """The correlator's noiseless reading (mm/s, ≥ 0) and how far apart the two sensors' tracks
    over the floor lie (mm), for the robot moving at ``vx`` forward, ``vy`` left (mm/s, robot
    frame, at the pivot) and turning at ``omega`` (rad/s, counter-clockwise).

    The sensor at x moves at w = (vx, vy + ω·x); the angle between w₁ and w₂ is the angle Δφ the
    pair makes at the centre of rotation, and their radii there are |wᵢ|/|ω|. The reading is
    L·|ω|/Δφ = (sin-side / Δφ)/|vx| with sin-side = |vx·ω·L|, written so that ω → 0 gives the
    straight line's |w|²/|vx| (= |vx| without side slip). The reading means nothing when the
    tracks miss: check the second value against the spot."""
    x1, x2 = mount.rear_mm, mount.front_mm
    spacing = x2 - x1
    w1 = (vx, vy + omega * x1)
    w2 = (vx, vy + omega * x2)
    n1, n2 = math.hypot(*w1), math.hypot(*w2)
    if n1 + n2 == 0.0:
        return 0.0, 0.0
    miss = spacing * abs(2 * vy + omega * (x1 + x2)) / (n1 + n2)
    dot = w1[0] * w2[0] + w1[1] * w2[1]
    if vx == 0.0 or dot <= 0.0:  # the floor crosses the axis, or runs opposite ways under the two
        return 0.0, max(miss, spacing)
    cross = abs(vx * omega * spacing)
    turned = math.atan2(cross, dot)
    ratio = cross / turned if turned > 0.0 else dot
    return ratio / abs(vx), miss


@dataclass(frozen=True)
class SampleTruth:
    """What one sample really was (the model's, for tests): the robot's motion over it and why
    the reading is what it is."""

    stamp_ms: float
    dt_ms: float
    vx: float
    vy: float
    omega: float
    forward_um: float  # the pivot's true forward translation over the sample
    correlated: bool  # the tracks met: the reading is L/τ (with noise), else bogus
    flipped: bool  # the reading's direction is wrong
    dynamic: bool
    increment_um: int  # what the sensor gave


class FloorCorrelator:
    """The sensor alone: a reading per sample from the robot's motion over it."""

    def __init__(self, rng: np.random.Generator, mount: Mount | None = None) -> None:
        self.rng = rng
        self.mount = mount or Mount()
        self.last_speed: float | None = None  # the previous sample's true forward speed, mm/s

    def period_ms(self) -> float:
        """The time to the next sample: over 40 ms, variable (seed table 3.1)."""
        return SAMPLE_MIN_MS + float(self.rng.uniform(0.0, SAMPLE_JITTER_MS))

    def sample(self, stamp_ms: float, dt_ms: float, vx: float, vy: float, omega: float) -> SampleTruth:
        """One reading for the motion over a sample of ``dt_ms`` (vx, vy mm/s at the pivot, robot
        frame; omega rad/s). Draws the same four numbers whatever the motion, so the stream
        stays in step with the samples."""
        noise, flip, coin, bogus = self.rng.normal(), self.rng.random(), self.rng.random(), self.rng.random()
        dt_s = dt_ms / 1000.0
        dynamic = self.last_speed is not None and abs(vx - self.last_speed) > DYNAMIC_MM_S2 * dt_s
        self.last_speed = vx
        speed, miss = correlated_speed(vx, vy, omega, self.mount)
        floor = math.hypot(vx, vy + omega * self.mount.x_mm)  # under the pair's midpoint, mm/s
        correlated = miss <= self.mount.spot_mm
        flipped = False
        if floor < STILL_MM_S:
            reading = 0.0
        elif correlated:
            flipped = flip < (FLIP_P_DYNAMIC if dynamic else FLIP_P)
            reading = math.copysign(speed, vx) * (1.0 + NOISE_REL * noise) * (-1.0 if flipped else 1.0)
        else:  # no correlation: the best peak of two unrelated signals
            reading = floor * (1.0 - BOGUS_SPREAD + 2 * BOGUS_SPREAD * bogus) * (1.0 if coin < 0.5 else -1.0)
        return SampleTruth(
            stamp_ms=stamp_ms,
            dt_ms=dt_ms,
            vx=vx,
            vy=vy,
            omega=omega,
            forward_um=vx * dt_s * 1000.0,
            correlated=correlated,
            flipped=flipped,
            dynamic=dynamic,
            increment_um=round(reading * dt_s * 1000.0),
        )


def correlator_rng(seed: int) -> np.random.Generator:
    """The correlator's own random stream of the world's ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(SEED_STREAM,)))


class CorrelatorDevice:
    """The floor correlator on the simulated robot: samples at variable times from the world's motion.

    The world's pose is known where it is asked (``pose_at`` now); between two reads the robot is
    taken to move and turn evenly, so each sample's motion is the pose's change over it and the
    samples' true translations add up to the move between the reads."""

    def __init__(self, sim: Any, correlator: FloorCorrelator | None = None) -> None:
        self.sim = sim
        self.clock = sim.clock
        self.correlator = correlator or FloorCorrelator(correlator_rng(int(sim.seed)))
        self.defective = sim.body == "seed"
        now = self.clock.now_ms()
        pose = sim.pose_at(now)
        self.seen = (now, pose.x, pose.y, pose.theta)  # time and pose of the last read
        self.last = self.seen  # time and pose at the last sample
        self.next_ms = now + self.correlator.period_ms()
        self.truth: list[SampleTruth] = []  # the last read's samples as they really were

    def read(self, _: dict[str, Any] | None = None) -> dict[str, Any]:
        """``hw/correlator/read``: every sample since the previous read (the newest last)."""
        with self.sim.lock:
            now = self.sim.advance()
            pose = self.sim.pose_at(now)
            powered = bool(self.sim.powered)
        if self.defective:
            return {"increments_um": [], "stamps_ms": [], "lost": 0, "power": powered, "defective": True}
        since, x0, y0, theta0 = self.seen
        span = max(now - since, 1e-9)
        turned = math.remainder(pose.theta - theta0, 2 * math.pi)
        truth: list[SampleTruth] = []
        while self.next_ms <= now:
            t = self.next_ms
            share = min(1.0, max(0.0, (t - since) / span))
            here = (t, x0 + (pose.x - x0) * share, y0 + (pose.y - y0) * share, theta0 + turned * share)
            truth.append(self._sample(self.last, here))
            self.last = here
            self.next_ms = t + self.correlator.period_ms()
        self.seen = (now, pose.x, pose.y, theta0 + turned)  # unwrapped, as the samples' headings
        lost = max(0, len(truth) - MAX_SAMPLES)
        kept = truth[lost:] if powered else []
        self.truth = kept
        return {
            "increments_um": [s.increment_um for s in kept],
            "stamps_ms": [s.stamp_ms for s in kept],
            "lost": lost if powered else 0,
            "power": powered,
            "defective": False,
        }

    def _sample(self, before: tuple[float, ...], after: tuple[float, ...]) -> SampleTruth:
        """The sample ending at ``after`` (time, x, y, heading) from the pose at ``before``."""
        dt_ms = max(after[0] - before[0], 1e-9)
        dx, dy, dtheta = after[1] - before[1], after[2] - before[2], after[3] - before[3]
        mid = before[3] + dtheta / 2
        forward = math.cos(mid) * dx + math.sin(mid) * dy
        left = -math.sin(mid) * dx + math.cos(mid) * dy
        per_s = 1000.0 / dt_ms
        return self.correlator.sample(after[0], dt_ms, forward * per_s, left * per_s, dtheta * per_s)

    def handle(self, what: str, request: dict[str, Any]) -> Any:
        """Answer a request below ``hw/`` (``correlator/read``)."""
        if what == "correlator/read":
            return self.read(request)
        raise HardwareRequestError(f"no hardware at hw/{what} (have: correlator/read)")
