"""Sensor synchronisation as in the Darmstadt program (seed 000, §5.3, §5.5, §6.3).

Raw samples from sensors that deliver at different rates go into a double ("shadow") buffer:
writers append to the active half under a lock held only for the append, so they are never
blocked by a synchronisation in progress. A :class:`Trigger` decides when to synchronise (at fixed
grid times of one sensor's time, after N samples of one sensor, or every K token rounds); the
buffer halves swap and one synchroniser per sensor turns the swapped half into one synchronised
record. Which sensors there are, in which order their synchronisers run and which synchroniser
each has is the registry's (:mod:`modules.localization.sensors`, one file per sensor); this module
holds the machinery they share — the buffer, the trigger, the odometry track and the synchronisers
of the built-in sensors, and :class:`SummedSync` that the gyro's and the correlator's build on
(``sensors/gyro.py``, ``sensors/correlator.py``):

==========  ======================================================================  ==========
sensor      synchronised as                                                         seed
==========  ======================================================================  ==========
odometry    sum of the step increments since the last sync (from cumulative counts)  odometry
compass     newest heading, or circular mean — each carried to the sync time         (ours)
gyro        mean of the rates since the last sync, and the turn they make           gyroscope
correlator  sum of the translation increments since the last sync                  correlator
sonar       newest distance of every sensor, plus every wall fitted in the period    walls
battery     newest voltages                                                          (ours)
truth       newest ground-truth pose (the world's: reference only, never fused)     (ours)
lops        newest distances and position (table 3.1)                               LOPS
==========  ======================================================================  ==========

Every sample carries the time stamp *of the sensor* (ms of simulated time), not of its arrival:
the odometry track (dead-reckoned pose per step-counter sample) lets the compass and sonar
synchronisers carry their samples to the exact sync time. :class:`SampleTiming` counts missed
samples (gaps in a sensor's sequence number, or in its stamps) and late ones (stamped before the
previous sync but arriving after it).

The period trigger (ours, the default) holds the seed's 100 ms cycle whatever rate the sensors
publish at or the token delivers: each synchronisation is stamped at a grid time ``k·period`` of
the trigger sensor's time and runs once a sample at or past it has arrived. The odometry sum is
then split at the grid time (the step counters interpolated there, whole half-steps; the rest
goes to the next synchronisation), compass and sonar samples are carried to it along the track,
and the ground truth is interpolated there (:class:`TruthSync`).
"""

from __future__ import annotations

import math
import threading
from bisect import bisect_left
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from modules.localization.walls import to_frame, wrap

NO_CONTACT_CM = 255
#: a compass sample this much newer than the newest step-counter sample is not judged yet
UNKNOWN_MOTION_MS = 60
#: a summed sensor's sample this much older than the sync time is not carried to it (it fell silent)
SUM_STALE_MS = 500
#: the period trigger catches up at most this many grid times behind its sensor's newest sample;
#: after a longer silence it jumps to the newest grid time (the grid times between are skipped)
CATCH_UP_PERIODS = 10


@dataclass(frozen=True)
class Sample:
    """One raw sample as a sensor delivered it: ``stamp_ms`` is the sensor's own time stamp."""

    sensor: str
    stamp_ms: int
    values: dict[str, Any]
    seq: int | None = None


# =============================================================================================
# the shadow buffer and the trigger


class ShadowBuffer:
    """Two raw-data buffers: writers fill the active one, a sync swaps and reads the other.

    ``write`` holds the lock only for one list append (never during a synchronisation), so a
    writer is never blocked for longer than another writer's append or the swap's flip.
    Every sample is filed under the *generation* of the buffer it went into; a log records it,
    so an offline replay can hand each synchronisation exactly the samples it had online.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._halves: list[dict[str, list[Sample]]] = [{}, {}]
        self._active = 0
        self._generation = 0
        self._latest: dict[str, Sample] = {}

    @property
    def generation(self) -> int:
        """The generation the next written sample belongs to."""
        return self._generation

    def write(self, sample: Sample) -> int:
        """File ``sample`` in the active half; returns the generation it belongs to."""
        with self._lock:
            self._halves[self._active].setdefault(sample.sensor, []).append(sample)
            self._latest[sample.sensor] = sample
            return self._generation

    def latest(self) -> dict[str, Sample]:
        """The sample written last of every sensor, whichever half it went into (a live view's)."""
        with self._lock:
            return dict(self._latest)

    def count(self, sensor: str) -> int:
        """How many samples of ``sensor`` the active half holds."""
        with self._lock:
            return len(self._halves[self._active].get(sensor, ()))

    def newest_stamp(self, sensor: str) -> int | None:
        """The stamp of the newest ``sensor`` sample in the active half (None: none yet)."""
        with self._lock:
            samples = self._halves[self._active].get(sensor)
            return samples[-1].stamp_ms if samples else None

    def oldest_stamp(self, sensor: str) -> int | None:
        """The earliest stamp of a ``sensor`` sample in the active half (None: none yet)."""
        with self._lock:
            samples = self._halves[self._active].get(sensor)
            return min(s.stamp_ms for s in samples) if samples else None

    def swap(self) -> tuple[int, dict[str, list[Sample]]]:
        """Flip the halves; returns the generation and the samples of the half just closed."""
        with self._lock:
            closed = self._halves[self._active]
            self._active ^= 1
            self._halves[self._active] = {}
            generation = self._generation
            self._generation += 1
        return generation, closed


class Trigger:
    """When to synchronise, and the time a synchronisation is stamped with.

    Three kinds: ``period_ms`` > 0 (ours, the default) synchronises at the grid times
    ``k·period_ms`` of ``sensor``'s time, as soon as a sample of it at or past the next grid time
    has arrived, and stamps the synchronisation with that grid time: exactly ``period_ms`` apart
    in sensor time, whatever rate the sensor publishes at or the token delivers (a late token
    delivery catches up one grid time per synchronisation, at most :data:`CATCH_UP_PERIODS`).
    Else after ``count`` samples of ``sensor`` (the seed's), ``min_period_ms`` also asking that
    the newest be that much sensor time after the previous synchronisation; or every ``rounds``
    token rounds. These two stamp a synchronisation with the newest sample's time.
    """

    def __init__(
        self,
        sensor: str | None = "odometry",
        count: int = 1,
        rounds: int | None = None,
        min_period_ms: int = 0,
        period_ms: int = 0,
    ) -> None:
        if (sensor is None) == (rounds is None):
            raise ValueError("a trigger needs exactly one of sensor or rounds")
        if period_ms < 0 or (period_ms and sensor is None):
            raise ValueError("a period trigger needs a sensor and a positive period")
        self.sensor = sensor
        self.count = count
        self.rounds = rounds
        self.min_period_ms = min_period_ms
        self.period_ms = period_ms
        self.last_sync_ms: int | None = None
        #: the period trigger: earliest and newest stamp of the sensor in the halves synchronised
        self.first_ms: int | None = None
        self.newest_ms: int | None = None
        self.skipped = 0  # grid times jumped over after a silence of the sensor
        self._last_counter: int | None = None

    def due(self, buffer: ShadowBuffer, counter: int | None = None) -> bool:
        """True when the synchronisation should run now (``counter``: the token's round counter)."""
        if self.sensor is not None and self.period_ms:
            newest = _newest(self.newest_ms, buffer.newest_stamp(self.sensor))
            first = buffer.oldest_stamp(self.sensor) if self.last_sync_ms is None else None
            grid = self.next_grid_ms(first)
            return newest is not None and grid is not None and newest >= grid
        if self.sensor is not None:
            if buffer.count(self.sensor) < self.count:
                return False
            if self.min_period_ms and self.last_sync_ms is not None:
                newest = buffer.newest_stamp(self.sensor)
                return newest is not None and newest - self.last_sync_ms >= self.min_period_ms
            return True
        if counter is None or self.rounds is None:
            return False
        if self._last_counter is None:
            self._last_counter = counter
            return False
        if (counter - self._last_counter) % 256 >= self.rounds:
            self._last_counter = counter
            return True
        return False

    def next_grid_ms(self, first_candidate: int | None = None) -> int | None:
        """The period trigger's next grid time: the first after the last synchronisation, or
        at or after the sensor's first sample (``first_candidate``: one not synchronised yet)."""
        period = self.period_ms
        if self.last_sync_ms is not None:
            return (self.last_sync_ms // period + 1) * period
        first = self.first_ms
        if first_candidate is not None:
            first = first_candidate if first is None else min(first, first_candidate)
        return None if first is None else -(-first // period) * period

    def stamp(self, half: dict[str, list[Sample]], fallback: int) -> int:
        """The time of the synchronisation of ``half`` (called once per synchronisation, online
        and in a replay: the period trigger's state follows the halves it stamps)."""
        if not self.period_ms:
            return sync_stamp(half, self.sensor, fallback)
        stamps = [s.stamp_ms for s in half.get(self.sensor or "", [])]
        if stamps:
            self.first_ms = _oldest(self.first_ms, min(stamps))
            self.newest_ms = _newest(self.newest_ms, max(stamps))
        grid = self.next_grid_ms()
        if grid is None or self.newest_ms is None or self.newest_ms < grid:
            # asked for before the grid time (not by due()): at the newest sample, as the count trigger
            return sync_stamp(half, self.sensor, fallback)
        behind = (self.newest_ms - grid) // self.period_ms
        if behind > CATCH_UP_PERIODS:
            self.skipped += behind
            grid += behind * self.period_ms
        return grid


def _newest(a: int | None, b: int | None) -> int | None:
    return b if a is None else a if b is None else max(a, b)


def _oldest(a: int | None, b: int) -> int:
    return b if a is None else min(a, b)


# =============================================================================================
# timing: missed and late samples


class SampleTiming:
    """Cycle times, missed and late samples of one sensor (the seed's time module)."""

    def __init__(self, sensor: str, period_ms: float | None = None, seq_modulo: int = 1 << 16) -> None:
        self.sensor = sensor
        self.period_ms = period_ms
        self.seq_modulo = seq_modulo
        self.samples = 0
        self.missed = 0
        self.late = 0
        self.last_stamp: int | None = None
        self.last_seq: int | None = None

    def observe(self, sample: Sample, last_sync_ms: int | None) -> None:
        """Account for one sample, in the order samples were synchronised."""
        self.samples += 1
        if last_sync_ms is not None and sample.stamp_ms < last_sync_ms:
            self.late += 1
        if sample.seq is not None and self.last_seq is not None:
            gap = (sample.seq - self.last_seq) % self.seq_modulo
            if gap > 1:
                self.missed += gap - 1
        elif sample.seq is None and self.period_ms and self.last_stamp is not None:
            gap_ms = sample.stamp_ms - self.last_stamp
            if gap_ms > 1.5 * self.period_ms:
                self.missed += round(gap_ms / self.period_ms) - 1
        if sample.seq is not None:
            self.last_seq = sample.seq
        self.last_stamp = sample.stamp_ms

    def as_dict(self) -> dict[str, int]:
        return {"samples": self.samples, "missed": self.missed, "late": self.late}


# =============================================================================================
# the odometry track: dead reckoning per step-counter sample, in the odometry frame


@dataclass(frozen=True)
class OdometryParams:
    """How half-steps become motion (the seed robot's motor, SPEC §3 motor)."""

    mm_per_step: float = 0.5419
    steps_per_degree: float = 6.5  # the glide factor μ: differential half-steps per degree turned
    model: str = "arc"  # "straight" (chord = mean track distance) or "arc" (exact chord of the arc)


def step_motion(
    dl: float,
    dr: float,
    params: OdometryParams,
    step_scale: float = 1.0,
    steps_per_degree: float | None = None,
) -> tuple[float, float]:
    """Distance ``s`` (mm, along the chord) and rotation ``ω`` (rad) of one step increment.

    ``ω = (Δr − Δl)/2 / μ`` in degrees; ``s`` is ``(Δl + Δr)/2 · mm_per_step`` for the
    straight model, and that times ``2·sin(ω/2)/ω`` (the chord of the arc) for the arc model.
    """
    mu = params.steps_per_degree if steps_per_degree is None else steps_per_degree
    omega = math.radians((dr - dl) / 2.0 / mu)
    s = (dl + dr) / 2.0 * params.mm_per_step * step_scale
    if params.model == "arc" and abs(omega) > 1e-9:
        s *= 2.0 * math.sin(omega / 2.0) / omega
    return s, omega


def advance(pose: tuple[float, float, float], s: float, omega: float) -> tuple[float, float, float]:
    """The seed's odometry state model: move ``s`` along ``ψ + ω/2``, then turn ``ω``."""
    x, y, psi = pose
    mid = psi + omega / 2.0
    return x + s * math.cos(mid), y + s * math.sin(mid), psi + omega


class OdometryTrack:
    """Dead-reckoned poses at the step counters' own time stamps, for the last few seconds.

    The frame is the odometry frame (continuous, never corrected); other synchronisers use it to
    carry samples to the sync time and to place sonar points relative to each other.
    """

    def __init__(self, params: OdometryParams, keep_ms: int = 20_000) -> None:
        self.params = params
        self.keep_ms = keep_ms
        self.stamps: deque[int] = deque()
        self.poses: deque[tuple[float, float, float]] = deque()

    def append(self, stamp_ms: int, pose: tuple[float, float, float]) -> None:
        if self.stamps and stamp_ms < self.stamps[-1]:
            stamp_ms = self.stamps[-1]  # a late counter sample: keep the track monotonic
        self.stamps.append(stamp_ms)
        self.poses.append(pose)
        while len(self.stamps) > 2 and self.stamps[-1] - self.stamps[1] > self.keep_ms:
            self.stamps.popleft()
            self.poses.popleft()

    def pose_at(self, stamp_ms: float) -> tuple[float, float, float] | None:
        """The odometry-frame pose at ``stamp_ms`` (linear between samples, held at the ends)."""
        if not self.stamps:
            return None
        stamps = self.stamps
        if stamp_ms <= stamps[0]:
            return self.poses[0]
        if stamp_ms >= stamps[-1]:
            return self.poses[-1]
        i = bisect_left(stamps, stamp_ms)
        t0, t1 = stamps[i - 1], stamps[i]
        p0, p1 = self.poses[i - 1], self.poses[i]
        f = (stamp_ms - t0) / (t1 - t0) if t1 > t0 else 1.0
        return (p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]), p0[2] + f * (p1[2] - p0[2]))


# =============================================================================================
# the per-sensor synchronisers


class OdometrySync:
    """Sum of the step increments since the last sync, from cumulative half-step counters.

    ``split_at_sync`` (the period trigger): the sum runs exactly to the sync time, not to the
    newest sample: the counters are interpolated linearly between the samples around the sync
    time, to whole half-steps (rounded half away from zero, so equal or opposite increments stay
    equal or opposite: a straight move stays straight, a turn on the spot a turn), and what lies
    after it goes to the next synchronisation. The sums add up to the counters' total exactly.
    """

    sensor = "odometry"

    def __init__(
        self,
        track: OdometryTrack,
        baseline: tuple[int, int] | None = (0, 0),
        split_at_sync: bool = False,
    ) -> None:
        # the counters the start pose belongs to: (0, 0) when the robot was put down at a known pose
        # as the motor started (its counters start at 0); None: the first sample's (pose from the motor)
        self.track = track
        self.last: tuple[int, int] | None = baseline
        self.pose = (0.0, 0.0, 0.0)  # odometry frame
        # when the motors were switched on or off (the stamp of the last sample before the
        # change): the compass subtracts their running field by what the ring last told it
        self.moving: bool | None = None
        self.changes: deque[int] = deque(maxlen=8)
        self.newest_ms: int | None = None
        self._previous_ms: int | None = None
        self.split_at_sync = split_at_sync
        #: split_at_sync: (stamp, left, right) half-steps counted since the baseline, per sample
        self.totals: deque[tuple[int, int, int]] = deque()
        self.counted = (0, 0)  # the totals at the last sync time (what earlier syncs summed)

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any]:
        dl_total = dr_total = 0
        for sample in samples:
            left, right = int(sample.values["steps_left"]), int(sample.values["steps_right"])
            self._note_motion(sample, left, right)
            if self.last is None:
                self.last = (left, right)
                self.track.append(sample.stamp_ms, self.pose)
                self._note_total(sample.stamp_ms, 0, 0)
                continue
            if not self.track.stamps:
                self.track.append(sample.stamp_ms, self.pose)
            dl = wrap_i32(left - self.last[0])
            dr = wrap_i32(right - self.last[1])
            self.last = (left, right)
            dl_total += dl
            dr_total += dr
            s, omega = step_motion(dl, dr, self.track.params)
            self.pose = advance(self.pose, s, omega)
            self.track.append(sample.stamp_ms, self.pose)
            self._note_total(sample.stamp_ms, dl, dr)
        if self.split_at_sync:
            at_sync = self.totals_at(sync_ms)
            dl_total, dr_total = at_sync[0] - self.counted[0], at_sync[1] - self.counted[1]
            self.counted = at_sync
            while len(self.totals) > 1 and self.totals[1][0] <= sync_ms:
                self.totals.popleft()  # keep the last sample at or before the sync time
        stamp = samples[-1].stamp_ms if samples else sync_ms
        return {"dl": dl_total, "dr": dr_total, "count": len(samples), "stamp_ms": stamp}

    def _note_total(self, stamp_ms: int, dl: int, dr: int) -> None:
        if not self.split_at_sync:
            return
        left, right = (self.totals[-1][1], self.totals[-1][2]) if self.totals else self.counted
        if self.totals and stamp_ms < self.totals[-1][0]:
            stamp_ms = self.totals[-1][0]  # a late counter sample: counted from the newest time on
        self.totals.append((stamp_ms, left + dl, right + dr))

    def totals_at(self, stamp_ms: int) -> tuple[int, int]:
        """The half-steps counted since the baseline at ``stamp_ms``: interpolated between the
        samples around it, held after the newest (whole half-steps, see the class)."""
        totals = self.totals
        if not totals:
            return self.counted
        if stamp_ms >= totals[-1][0]:
            return totals[-1][1], totals[-1][2]
        i = bisect_left([t[0] for t in totals], stamp_ms)
        if i == 0:
            return totals[0][1], totals[0][2]
        (t0, l0, r0), (t1, l1, r1) = totals[i - 1], totals[i]
        f = (stamp_ms - t0) / (t1 - t0)
        return l0 + _round_away(f * (l1 - l0)), r0 + _round_away(f * (r1 - r0))

    def _note_motion(self, sample: Sample, left: int, right: int) -> None:
        """Record a start or stop of the motors (motor state MOVING, else steps made)."""
        state = sample.values.get("state")
        if state is not None:
            moving = int(state) == 1
        else:
            moving = self.last is not None and (left, right) != self.last
        if self.moving is not None and moving != self.moving:
            self.changes.append(self._previous_ms if self._previous_ms is not None else sample.stamp_ms)
        self.moving = moving
        self._previous_ms = sample.stamp_ms
        self.newest_ms = sample.stamp_ms if self.newest_ms is None else max(self.newest_ms, sample.stamp_ms)

    def settling(self, stamp_ms: int, settle_ms: int) -> bool:
        """True if the motors started or stopped within ``settle_ms`` before ``stamp_ms``, or the
        step counters have not yet reported that far (what the motors did then is not known)."""
        if settle_ms <= 0:
            return False
        if self.newest_ms is None or stamp_ms > self.newest_ms + UNKNOWN_MOTION_MS:
            return True
        return any(change <= stamp_ms < change + settle_ms for change in self.changes)


class CompassSync:
    """Newest heading or circular mean, each sample carried to the sync time with the odometry.

    Wire headings are the navigation convention (0 = north, clockwise, 1/100 degree); the result
    is radians, counter-clockwise from +X, with north at ``north_deg`` (CCW from +X).
    """

    sensor = "compass"
    USABLE_STATES = (1,)  # compass_state OK; UNCALIBRATED, DISTURBED, CALIBRATING are skipped

    def __init__(
        self,
        track: OdometryTrack,
        mode: str = "newest",
        north_deg: float = 90.0,
        motion: OdometrySync | None = None,
        settle_ms: int = 0,
    ) -> None:
        self.track = track
        self.mode = mode
        self.north = math.radians(north_deg)
        self.motion = motion
        self.settle_ms = settle_ms
        self.skipped = 0
        self.settling = 0

    def heading(self, sample: Sample) -> float:
        """The sample's heading in the internal convention (rad, CCW from +X)."""
        return wrap(self.north - math.radians(sample.values["heading_cdeg"] / 100.0))

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any] | None:
        usable = [s for s in samples if s.values.get("state", 1) in self.USABLE_STATES]
        self.skipped += len(samples) - len(usable)
        if self.motion is not None and self.settle_ms > 0:
            # the compass module subtracts the motors' running field while the ring says they
            # run: it learns of a start or stop a token round late, and its mean carries it on
            steady = [s for s in usable if not self.motion.settling(s.stamp_ms, self.settle_ms)]
            self.settling += len(usable) - len(steady)
            usable = steady
        if not usable:
            return None
        chosen = usable[-1:] if self.mode == "newest" else usable
        at_sync = self.track.pose_at(sync_ms)
        carried = []
        for sample in chosen:
            heading = self.heading(sample)
            at_sample = self.track.pose_at(sample.stamp_ms)
            if at_sync is not None and at_sample is not None:
                heading += at_sync[2] - at_sample[2]
            carried.append(heading)
        mean = math.atan2(sum(math.sin(h) for h in carried), sum(math.cos(h) for h in carried))
        return {"heading": wrap(mean), "count": len(usable), "stamp_ms": usable[-1].stamp_ms}


class SummedSync:
    """A sensor that publishes a running sum (the gyro's angle, the correlator's translation),
    synchronised as table 3.1 asks — the mean of the rates, the sum of the increments — from the
    sum's difference between two synchronisation times.

    The token carries only the newest sample of such a sensor, so a difference of the sums counts
    every sample the sensor took, carried or not. The sum at a sync time is interpolated between
    the samples around it, or carried there from the nearest sample by what the odometry track
    did in between (:meth:`track_change`). A sample not in the running state ends the sum (a
    calibration, a reset): the next amount is counted from the next synchronisation on; so does
    a sensor silent for :data:`SUM_STALE_MS`.
    """

    sensor = ""
    field = ""  # the running sum's field and its scale to the record's unit
    scale = 1.0
    running_state = 0
    amount_key, rate_key = "amount", "rate"  # the record's names for the amount and amount per s

    def __init__(self, track: OdometryTrack) -> None:
        self.track = track
        self.recent: list[tuple[int, float]] = []  # (stamp, sum), oldest first
        self.reference: tuple[int, float] | None = None  # the last sync's time and sum there
        self.skipped = 0  # samples not in the running state
        self.epoch = 0  # how often the sum started again

    def track_change(self, older: tuple[float, float, float], newer: tuple[float, float, float]) -> float:
        """What the sum would have grown by between two odometry-track poses."""
        raise NotImplementedError

    def sum_at(self, sync_ms: int) -> float | None:
        """The sum at ``sync_ms``; None without a recent enough sample."""
        known = self.recent
        if not known or sync_ms - known[-1][0] > SUM_STALE_MS:
            return None
        after = next((i for i, (t, _) in enumerate(known) if t >= sync_ms), None)
        if after is not None and after > 0:
            (t0, a0), (t1, a1) = known[after - 1], known[after]
            return a1 if t1 == t0 else a0 + (sync_ms - t0) / (t1 - t0) * (a1 - a0)
        stamp, value = known[-1] if after is None else known[0]
        at_sync, at_sample = self.track.pose_at(sync_ms), self.track.pose_at(stamp)
        if at_sync is not None and at_sample is not None:
            value += self.track_change(at_sample, at_sync)
        return value

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any] | None:
        running = []
        for sample in samples:
            if int(sample.values.get("state", self.running_state)) != self.running_state:
                if self.recent or self.reference is not None:
                    self.epoch += 1
                self.recent.clear()
                self.reference = None
                self.skipped += 1
                continue
            running.append(sample)
            self.recent.append((sample.stamp_ms, float(sample.values[self.field]) * self.scale))
        self.recent.sort()
        value = self.sum_at(sync_ms)
        reference, self.reference = self.reference, None if value is None else (sync_ms, value)
        before = [i for i, (t, _) in enumerate(self.recent) if t <= sync_ms]
        if before:
            del self.recent[: before[-1]]  # keep the last sample at or before the sync time
        if value is None or reference is None or sync_ms <= reference[0]:
            return None
        amount = value - reference[1]
        return {
            self.rate_key: amount / ((sync_ms - reference[0]) / 1000.0),
            self.amount_key: amount,
            "sum": value,
            "epoch": self.epoch,
            "count": len(running),
            "stamp_ms": running[-1].stamp_ms if running else sync_ms,
        }


class SonarSync:
    """Newest distance of every sonar plus every wall the :class:`WallDetector` fitted."""

    sensor = "sonar"

    def __init__(self, track: OdometryTrack, detector: Any | None, gauge: Any | None = None) -> None:
        self.track = track
        self.detector = detector
        self.gauge = gauge
        self.newest: list[int | None] | None = None

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any] | None:
        travel: list[dict[str, Any]] = []
        for sample in samples:
            self.newest = [None if d == NO_CONTACT_CM else int(d) * 10 for d in sample.values["distances"]]
            pose = self.track.pose_at(sample.stamp_ms)
            if pose is not None:
                if self.detector is not None:
                    self.detector.add(sample.stamp_ms, pose, self.newest)
                if self.gauge is not None:
                    travel.extend(self.gauge.add(pose, self.newest))
        if not samples:
            return None
        at_sync = self.track.pose_at(sync_ms)
        walls = self.detector.detect(at_sync) if self.detector is not None and at_sync is not None else []
        record: dict[str, Any] = {
            "distances_mm": list(self.newest or []),
            "walls": walls,
            "count": len(samples),
            "stamp_ms": samples[-1].stamp_ms,
        }
        newest_at = self.track.pose_at(samples[-1].stamp_ms)
        if newest_at is not None and at_sync is not None:
            record["at"] = relative_pose(newest_at, at_sync)  # where the newest distances were read
        if travel:
            for fit in travel:  # where the run ended, seen from the pose at the sync
                end_pose = fit.pop("end_pose")
                fit["end"] = relative_pose(end_pose, at_sync) if at_sync is not None else [0.0, 0.0, 0.0]
            record["travel"] = travel
        return record


def relative_pose(pose: tuple[float, float, float], reference: tuple[float, float, float]) -> list[float]:
    """``pose`` in the frame of ``reference`` (both odometry-frame poses): [x, y, heading]."""
    return [*to_frame((pose[0], pose[1]), reference), wrap(pose[2] - reference[2])]


class NewestSync:
    """The newest sample's values (battery; the truth when no period trigger stamps the syncs)."""

    def __init__(self, sensor: str) -> None:
        self.sensor = sensor

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any] | None:
        if not samples:
            return None
        newest = samples[-1]
        return {**newest.values, "count": len(samples), "stamp_ms": newest.stamp_ms}


class DueSync:
    """The newest sample *measured* by the sync time: one stamped on arrival (LOPS) was measured
    ``delay_ms`` before its stamp. A sample measured after the sync time waits for the next one:
    the token brings the odometry that triggers a sync later than Zenoh brings such a sample
    (at ``--speed 10`` hundreds of ms of emulated time), and a position from after the sync time
    taken as at it put the filter ahead of the robot."""

    def __init__(self, sensor: str, delay_ms: float = 0.0) -> None:
        self.sensor = sensor
        self.delay_ms = delay_ms
        self.waiting: list[Sample] = []

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any] | None:
        known = self.waiting + samples
        due = [s for s in known if s.stamp_ms - self.delay_ms <= sync_ms]
        self.waiting = [s for s in known if s.stamp_ms - self.delay_ms > sync_ms]
        if not due:
            return None
        newest = due[-1]
        return {**newest.values, "count": len(due), "stamp_ms": newest.stamp_ms}


class TruthSync:
    """The ground truth at the sync time: interpolated between the samples around it (the
    period trigger stamps a synchronisation before the newest samples), else the nearest one.

    A reference for the logs only (source ``T``); its time must match the other records'.
    """

    sensor = "truth"

    def __init__(self) -> None:
        self.recent: list[Sample] = []  # the newest samples of earlier halves

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any] | None:
        if not samples:
            return None
        known = sorted(self.recent + samples, key=lambda s: s.stamp_ms)
        self.recent = known[-4:]
        after = next((i for i, s in enumerate(known) if s.stamp_ms >= sync_ms), None)
        if after is None or after == 0:
            nearest = known[-1] if after is None else known[0]
            return {**nearest.values, "count": len(samples), "stamp_ms": nearest.stamp_ms}
        a, b = known[after - 1], known[after]
        if b.stamp_ms == sync_ms:
            return {**b.values, "count": len(samples), "stamp_ms": sync_ms}
        f = (sync_ms - a.stamp_ms) / (b.stamp_ms - a.stamp_ms)
        va, vb = a.values, b.values
        return {
            "x": va["x"] + f * (vb["x"] - va["x"]),
            "y": va["y"] + f * (vb["y"] - va["y"]),
            "theta": wrap(va["theta"] + f * wrap(vb["theta"] - va["theta"])),
            "count": len(samples),
            "stamp_ms": sync_ms,
        }


@dataclass
class SyncResult:
    """One synchronisation: its generation, time (sensor time, ms) and one record per sensor."""

    generation: int
    stamp_ms: int
    data: dict[str, dict[str, Any]] = field(default_factory=dict)


def sync_stamp(samples: dict[str, list[Sample]], trigger_sensor: str | None, fallback: int) -> int:
    """The time of a synchronisation: the newest stamp of the trigger sensor (else of anything)."""
    if trigger_sensor and samples.get(trigger_sensor):
        return max(s.stamp_ms for s in samples[trigger_sensor])
    stamps = [s.stamp_ms for group in samples.values() for s in group]
    return max(stamps) if stamps else fallback


def _round_away(value: float) -> int:
    """To the nearest whole number, halves away from zero (symmetric: -x gives -(x))."""
    return int(math.copysign(math.floor(abs(value) + 0.5), value))


def wrap_i32(value: int) -> int:
    """``value`` as the i32 it wraps to on the wire."""
    return (value + (1 << 31)) % (1 << 32) - (1 << 31)
