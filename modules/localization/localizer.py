"""The Darmstadt program on the ring: synchronisation, EKF, position store and logs.

Two layers:

- :class:`LocalizationCore` — no ring: raw samples in (:meth:`~LocalizationCore.feed`),
  synchronised data, filter, positions and log records out. ``tokenring replay`` runs exactly
  this code on a recorded log, so offline results equal the online ones bit for bit.
- :class:`Localizer` — the on-ring component a module program hosts (copro in this robot):

  .. code-block:: python

     class Program(UserProgram):
         def setup(self):
             self.loc = Localizer(self.os)          # config/localization.yaml by default
             self.loc.setup()                       # subscribes motor/compass/sonar/charger.data
             self.data = self.os.publish()
         def run(self):
             while self.running:
                 self.os.wait_visit(0.05)
                 self.loc.step()                    # new samples -> shadow buffer -> sync + EKF
                 self.data.write(**self.loc.copro_fields())   # pose_* fields of copro.data
         def teardown(self):
             self.loc.close()                       # closes the logs

  :meth:`Localizer.pose` returns :class:`LocalizedPose`: ``x_mm``, ``y_mm``, ``heading`` (rad,
  counter-clockwise from +X), validity flags per coordinate and the source (``ekf``,
  ``odometry`` or ``none``). In exploration mode the host hands over the map's walls with
  :meth:`Localizer.add_map_wall`; :meth:`Localizer.set_pose` re-initialises the pose (what
  ``SET_GLOBAL_POSITION`` does to the motor).

Samples are stamped by the sensors (``stamp_ms`` of each data channel); a new sample is seen when
a channel's stamp (or sequence number) changes between two token visits. The ground truth, when
a world simulator runs, arrives over Zenoh (``world/truth``) from a second thread — a concurrent
writer of the shadow buffer — and is logged as a reference (source ``T``), never fused.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from modules.localization.config import load_config
from modules.localization.ekf import PoseEKF
from modules.localization.logs import CLASS_LEVELS, DEFAULT_DEBUG_LEVEL, DataLog, ErrorLog
from modules.localization.lops_init import LopsInitialiser
from modules.localization.params import (
    detector_params,
    ekf_params,
    odometry_params,
    sonar_mounts,
    start_pose_of,
    trigger_of,
    with_body,
)
from modules.localization.sensors import SyncContext, registered, sensor_named, sensor_of_letter
from modules.localization.sync import (
    CATCH_UP_PERIODS,
    OdometryTrack,
    Sample,
    SampleTiming,
    ShadowBuffer,
    SyncResult,
    advance,
    step_motion,
)
from modules.localization.travel_corrections import TravelCorrections
from modules.localization.wall_corrections import WallCorrections
from modules.localization.walls import (
    GaugeParams,
    KnownWall,
    TravelGauge,
    WallDetector,
    load_known_room,
    wrap,
)
from modules.variants import algorithm

logger = logging.getLogger("tokenring.localization")

SOURCE_CODES = {"none": 0, "odometry": 1, "ekf": 2}
#: gyro readings rejected in a row after which its offset is learned afresh
GYRO_RELEARN_AFTER = 5


def __getattr__(name: str) -> Any:
    """The sensors' tables, worked out from the registry when read (PEP 562): :data:`CHANNELS`
    (the data channel read for each sensor), :data:`SEQ_FIELDS` (the field numbering its
    samples), :data:`VALUE_FIELDS` (the fields taken)."""
    if name == "CHANNELS":
        return {s.name: s.channel for s in registered() if s.channel is not None}
    if name == "SEQ_FIELDS":
        return {s.name: s.seq_field for s in registered() if s.seq_field is not None}
    if name == "VALUE_FIELDS":
        return {s.name: s.value_fields for s in registered() if s.channel is not None}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _settings(config: dict[str, Any], name: str) -> dict[str, Any]:
    """``sensors.<name>`` of ``config``; the sensor's defaults for one registered after the
    configuration was validated."""
    settings = config["sensors"].get(name)
    if settings is None:
        sensor = sensor_named(name)
        return dict(sensor.settings) if sensor is not None else {"use": False}
    return settings


def _letter(name: str) -> str:
    """The log source letter of the sensor ``name``."""
    sensor = sensor_named(name)
    if sensor is None:
        raise KeyError(f"no sensor {name!r} is registered")
    return sensor.letter


@dataclass(frozen=True)
class LocalizedPose:
    """The pose the Localizer offers: mm, radians counter-clockwise, validity per coordinate."""

    x_mm: float
    y_mm: float
    heading: float
    valid_x: bool
    valid_y: bool
    valid_heading: bool
    source: str
    stamp_ms: int
    #: the filter's standard deviations (x mm, y mm, heading rad); None without a filter
    sigmas: tuple[float, float, float] | None = None

    @property
    def valid_bits(self) -> int:
        """The ``pose_valid`` byte of copro.data: bit 0 x, bit 1 y, bit 2 heading."""
        return int(self.valid_x) | int(self.valid_y) << 1 | int(self.valid_heading) << 2


class LocalizationCore(WallCorrections, TravelCorrections):
    """Samples in; synchronised data, EKF, positions and log records out. No ring, no clock.

    Everything it computes depends only on the samples fed, the order they were fed in, the
    buffer generation each went into and the events (pose set, map walls) — all of which the
    data log records, so :mod:`modules.pc.replay` can run it again to the same bits.

    The sonar's corrections are parts of their own: against the known walls
    (:class:`~modules.localization.wall_corrections.WallCorrections`) and of the floor's step scale
    (:class:`~modules.localization.travel_corrections.TravelCorrections`); what the configuration
    makes of the filter, the detector and the trigger is :mod:`modules.localization.params`.
    """

    def __init__(
        self,
        config: dict[str, Any],
        *,
        data_log: DataLog | None = None,
        error_log: ErrorLog | None = None,
        known_walls: list[KnownWall] | None = None,
        start_pose: tuple[float, float, float] | None = None,
    ) -> None:
        self.config = config
        self.data_log = data_log
        self.error_log = error_log
        #: the MessageHandler's (seed §6.8.3, :meth:`message`): the newest messages, kept for a
        #: screen that opens later, and who is told of each one as it comes
        self.messages: deque[dict[str, Any]] = deque(maxlen=1000)
        self.messages_said = 0  # every message since the start: the next one's number
        self.message_listeners: list[Callable[[dict[str, Any]], None]] = []
        self._messages_lock = threading.Lock()
        #: the sensors registered as the core was built, in synchronisation order
        self.registry = registered()
        #: the settings (``sensors.<name>``) of every sensor used, in synchronisation order
        self.sensors = {
            sensor.name: settings
            for sensor in self.registry
            if (settings := _settings(config, sensor.name))["use"]
        }
        self.trigger = trigger_of(config)
        on_grid = self.trigger.period_ms > 0  # records stamped at grid times, before the newest samples
        self.buffer = ShadowBuffer()
        self.odometry = odometry_params(config)
        self.track = OdometryTrack(self.odometry)
        walls_mode = config["walls"]["mode"]
        self.detector = (
            WallDetector(sonar_mounts(config), detector_params(config))
            if walls_mode != "off" and "sonar" in self.sensors
            else None
        )
        #: one synchroniser per registered sensor, built by its file in synchronisation order
        context = SyncContext(
            config, self.track, on_grid, detector=self.detector, gauge=self._travel_gauge(config)
        )
        for sensor in self.registry:
            context.built[sensor.name] = sensor.synchroniser(context)
        self.synchronisers: dict[str, Any] = context.built
        self.timing = {
            sensor.name: SampleTiming(sensor.name, float(_settings(config, sensor.name)["period_ms"]) or None)
            for sensor in self.registry
        }
        #: round obstacles of the wall file's room: a beam meets them before the wall behind
        self.known_circles: list[tuple[float, float, float]] = []
        if walls_mode == "darmstadt" and known_walls is None:
            self.known_walls, self.known_circles = load_known_room(config["walls"]["file"])
        else:
            self.known_walls = list(known_walls or [])
        self.ekf_params = ekf_params(config)
        self.ekf: PoseEKF | None = None
        #: initial_pose lops: the filter starts once LOPS has measured before and after a drive
        init = config["lops"]["init"]
        self.lops_init = (
            LopsInitialiser(
                init["fixes"],
                init["drive_mm"],
                init["max_turn_deg"],
                init["settle_ms"],
                config["lops"]["sigma_mm"],
            )
            if config["filter"]["initial_pose"] == "lops"
            else None
        )
        self.dead_reckoning: tuple[float, float, float] | None = None
        #: the heading by summing the gyroscope's turns from the start pose's (its G position)
        self.gyro_heading: float | None = None
        if start_pose is None:
            start_pose = start_pose_of(config)
        if start_pose is not None:
            self._initialise(start_pose)
        self.positions: dict[str, dict[str, Any]] = {}
        self.last_sync_ms: int | None = None
        self.syncs = 0
        self.walls_unassociated = 0
        self.walls_associated = 0
        self.walls_repeated = 0  # fits of a wall from where it was last corrected with: not used
        self.walls_past_end = 0  # known walls passed over: the fit's sensors beyond their ends
        self.wall_corrected_at: dict[int, tuple[float, float, float]] = {}
        self.compass_skipped_turning = 0
        self.correlator_skipped_turning = 0
        self.gyro_skipped_turning = 0
        self.gyro_epoch = 0
        self.gyro_rejected_in_row = 0
        self.gyro_relearned = 0
        #: the walls.ahead ranges: used, or why not
        self.ahead = dict.fromkeys(
            ("used", "rejected", "repeated", "ambiguous", "not_square", "unexpected", "unconfirmed"), 0
        )
        self.ahead_corrected_at: dict[int, tuple[float, float]] = {}
        #: (sensor, wall) -> (stamp, innovation) of the last range that passed the other checks
        self.ahead_candidate: dict[tuple[int, int], tuple[int, float]] = {}
        self.travel = {
            "used": 0,
            "assumed_square": 0,
            "below_bound": 0,
            "oblique": 0,
            "unknown": 0,
            "rejected": 0,
            "waited": 0,
        }
        #: fits whose wall the robot's own map does not have yet: (stamp, beam origin, direction, fit)
        self.pending_travel: list[tuple[int, tuple[float, float], float, dict[str, Any]]] = []
        self._last_loss_message = -1000
        self._feed_lock = threading.Lock()
        self._fed = 0
        self._events: list[tuple[int, str, dict[str, Any]]] = []
        self._events_lock = threading.Lock()
        self.message("I", 0, f"localisation started: sensors {', '.join(self.sensors)}; walls {walls_mode}")

    def _travel_gauge(self, config: dict[str, Any]) -> TravelGauge | None:
        travel = config["filter"]["travel"]
        if not travel["enabled"] or "sonar" not in self.sensors:
            return None
        late = config["walls"]["sonar_late"] if config["walls"]["range_model"] == "tangent" else None
        params = GaugeParams(
            max_range_mm=travel["max_range_mm"],
            late_from_mm=late["from_mm"] if late else 0.0,
            late_mm_per_m=late["mm_per_m"] if late else 0.0,
        )
        return TravelGauge(sonar_mounts(config), params)

    # ---------------------------------------------------------------------------------------
    # input

    def feed(self, sample: Sample) -> int:
        """File a raw sample in the shadow buffer (any thread); logs it; returns its generation."""
        if sample.sensor not in self.sensors:
            return self.buffer.generation
        with self._feed_lock:
            number = self._fed
            self._fed += 1
            generation = self.buffer.write(sample)
            if self.data_log is not None and self.sensors[sample.sensor]["log_raw"]:
                payload: dict[str, Any] = {"gen": generation, "n": number, "v": sample.values}
                if sample.seq is not None:
                    payload["seq"] = sample.seq
                self.data_log.write(sample.stamp_ms, _letter(sample.sensor), "R", payload)
        return generation

    def event(self, kind: str, **payload: Any) -> None:
        """Queue an event (``set_pose``, ``map_wall``) for the next synchronisation; logged."""
        self.queue_event(self.buffer.generation, kind, payload)

    def queue_event(self, generation: int, kind: str, payload: dict[str, Any]) -> None:
        """File an event for the synchronisation of ``generation`` (replay gives the logged one)."""
        with self._events_lock:
            self._events.append((generation, kind, payload))
        if self.data_log is not None:
            stamp = self.last_sync_ms or 0
            source, letter = ("W", "W") if kind == "map_wall" else ("S", "E")
            self.data_log.write(stamp, source, letter, {"gen": generation, "event": kind, **payload})

    def _correct_lops(self, lops: dict[str, Any], stamp: int) -> None:
        """LOPS's distances, each one a correction: a position also from one or two good receivers
        (seed 000: the filter can use what lopscpp could not trilaterate)."""
        assert self.ekf is not None
        settings = self.config["lops"]
        receivers = settings["receivers"]
        moved, speed = self._moved_since(int(lops.get("stamp_ms", stamp)) - settings["delay_ms"], stamp)
        # the delay's spread, turned into distance by the speed the robot went meanwhile
        sigma = math.hypot(settings["sigma_mm"], speed * settings["delay_sigma_ms"] / 1000.0)
        for receiver, key in zip(receivers, ("d1", "d2", "d3"), strict=True):
            distance = lops.get(key)
            if distance is not None and not self.ekf.correct_range(
                (receiver[0], receiver[1]), distance, sigma, moved
            ):
                self.message(
                    "W",
                    stamp,
                    f"LOPS {key} = {distance:.0f} mm rejected by the gate (NIS {self.ekf.last_nis:.1f})",
                )
        # an error the packets share (the motion model between them, the receivers' places, and
        # moving, when they were measured: a WLAN stall or a late LOPS delays a run of them
        # alike): taken as independent, 30 distances a second would average it away
        floor = math.hypot(settings["floor_mm"], speed * settings["delay_sigma_ms"] / 1000.0)
        for axis in (0, 1):
            self.ekf.P[axis, axis] = max(self.ekf.P[axis, axis], floor * floor)

    def _correct_gyro(self, gyro: dict[str, Any], turn_rate: float, stamp: int) -> None:
        """The gyro's summed angle as a heading, at rest or on a straight leg only: turning, the
        world moves the robot a little after the motor's stamps say (the token's delay), so a
        sum taken mid-turn disagrees with the steps by the turn rate times that delay."""
        assert self.ekf is not None
        settings = self.config["filter"]["gyro"]
        if gyro["epoch"] != self.gyro_epoch:
            self.gyro_epoch = gyro["epoch"]
            self.ekf.restart_gyro()  # a new calibration: its sum starts again at 0
        if turn_rate > settings["max_turn_rate_deg_s"] or self.synchronisers["odometry"].settling(
            stamp, settings["settle_ms"]
        ):
            self.gyro_skipped_turning += 1
            return
        if self.ekf.correct_gyro(float(gyro["sum"]), math.radians(settings["sigma_deg"])):
            self.gyro_rejected_in_row = 0
            return
        self.message("W", stamp, f"gyroscope rejected by the gate (NIS {self.ekf.last_nis:.1f})")
        self.gyro_rejected_in_row += 1
        if self.gyro_rejected_in_row >= GYRO_RELEARN_AFTER:
            # its sum and the filter's heading parted (a scale error beyond the model's, a bump):
            # rejected readings never move the offset, so it is learned afresh from the next one
            self.ekf.restart_gyro()
            self.gyro_relearned += 1
            self.gyro_rejected_in_row = 0
            self.message(
                "W",
                stamp,
                f"gyroscope: {GYRO_RELEARN_AFTER} readings rejected in a row, its offset learned afresh",
            )

    def _correlator_travel(
        self, correlator: dict[str, Any] | None, omega: float, dt_s: float
    ) -> tuple[float, float] | None:
        """The floor correlator's distance over the synchronisation period and its σ; None while
        the robot turns faster than the correlator can follow (its increments are too large then,
        and on the spot bogus: seed §3.3)."""
        if correlator is None or dt_s <= 0:
            return None
        settings = self.config["filter"]["correlator"]
        if abs(math.degrees(omega)) / dt_s > settings["max_turn_rate_deg_s"]:
            self.correlator_skipped_turning += 1
            return None
        distance = float(correlator["distance"])
        return distance, math.hypot(settings["sigma_mm"], settings["sigma_rel"] * distance)

    def _moved_since(self, since_ms: float, stamp: int) -> tuple[tuple[float, float], float]:
        """How far the robot went from ``since_ms`` to the sync time ``stamp`` by the odometry track,
        turned into the filter's frame (mm), and its speed then (mm/s)."""
        at_sync, before = self.track.pose_at(stamp), self.track.pose_at(since_ms)
        if at_sync is None or before is None or self.ekf is None or stamp <= since_ms:
            return (0.0, 0.0), 0.0
        dx, dy = at_sync[0] - before[0], at_sync[1] - before[1]
        turn = self.ekf.pose[2] - at_sync[2]  # the odometry frame into the filter's
        c, s = math.cos(turn), math.sin(turn)
        moved = (c * dx - s * dy, s * dx + c * dy)
        return moved, math.hypot(dx, dy) / ((stamp - since_ms) / 1000.0)

    def message(self, cls: str, stamp_ms: int, text: str) -> None:
        """The MessageHandler (seed §6.8.3): a message of class ``cls`` (I W E F D, table B.5) to
        the error log, to the backlog (:attr:`messages`, the last 1000 as ``{n, class, stamp_ms,
        text}``) and to every listener in :attr:`message_listeners` (on the caller's thread; the
        entry is shared, not to be changed). Only the classes the debug level shows, as the error
        log keeps them (the seed's Debuglevel 0-4)."""
        if self.error_log is not None:
            self.error_log.message(cls, stamp_ms, text)
        if CLASS_LEVELS.get(cls, 0) > self.config.get("logs", {}).get("debug_level", DEFAULT_DEBUG_LEVEL):
            return
        with self._messages_lock:
            entry = {"n": self.messages_said, "class": cls, "stamp_ms": int(stamp_ms), "text": text}
            self.messages_said += 1
            self.messages.append(entry)
        for listener in list(self.message_listeners):
            try:
                listener(entry)
            except Exception:  # a screen's trouble is never the localisation's
                logger.exception("a message listener failed")

    # ---------------------------------------------------------------------------------------
    # synchronisation

    def maybe_sync(self, counter: int | None = None) -> SyncResult | None:
        """Synchronise if the trigger says so (``counter``: the token's round counter); the
        period trigger catches up on every grid time passed since the last visit. Returns the
        last synchronisation run (None: none)."""
        if not self.config["sync"]["enabled"]:
            return None
        result = None
        for _ in range(CATCH_UP_PERIODS + 1):
            if not self.trigger.due(self.buffer, counter):
                break
            result = self.synchronise()
            if not self.trigger.period_ms:
                break
        return result

    def synchronise(self) -> SyncResult:
        """Swap the shadow buffer and process the half just closed."""
        generation, half = self.buffer.swap()
        return self.synchronise_half(generation, half)

    def synchronise_half(self, generation: int, half: dict[str, list[Sample]]) -> SyncResult:
        """Run every synchroniser on one buffer half, then the filter (replay calls this too)."""
        stamp = self.trigger.stamp(half, self.last_sync_ms or 0)
        data: dict[str, dict[str, Any]] = {}
        lost: list[str] = []
        for name in self.synchronisers:
            if name not in self.sensors:
                continue
            samples = half.get(name, [])
            timing = self.timing[name]
            missed, late = timing.missed, timing.late
            for sample in samples:
                timing.observe(sample, self.last_sync_ms)
            if timing.missed > missed:
                lost.append(f"{name}: {timing.missed - missed} samples missed")
            if timing.late > late:
                self.message(
                    "W", stamp, f"{name}: {timing.late - late} late samples (stamped before the last sync)"
                )
            if not self.sensors[name].get("synchronise", True):
                continue  # its raw samples only (seed [Sensors]: Synchronisieren no)
            result = self.synchronisers[name].synchronise(samples, stamp)
            if name == "odometry" and samples and "x_mm" in samples[-1].values:
                v = samples[-1].values
                result["motor"] = [v["x_mm"], v["y_mm"], v["angle_cdeg"]]
            if result is not None:
                data[name] = result
        if lost and stamp - self._last_loss_message >= 1000:  # at most one report per simulated second
            self._last_loss_message = stamp
            self.message("E", stamp, "; ".join(lost))
        if self.data_log is not None:
            for name, record in data.items():
                if self.sensors[name]["log_sync"]:
                    self.data_log.write(stamp, _letter(name), "C", {"gen": generation, **record})
        counts = {name: len(half.get(name, [])) for name in self.sensors}
        self.process_synchronised(generation, stamp, data, counts)
        self.trigger.last_sync_ms = stamp
        return SyncResult(generation, stamp, data)

    # ---------------------------------------------------------------------------------------
    # filter and positions

    def _initialise(self, pose: tuple[float, float, float]) -> None:
        self.dead_reckoning = pose
        if self.config["filter"]["enabled"] and self.lops_init is None:
            self.ekf = PoseEKF(self.ekf_params, pose)

    def _initialise_by_lops(self, stamp: int, moving: bool, s: float, omega: float, lops: Any) -> None:
        """Seed 000 §8: the filter's first pose from LOPS's positions around a straight drive."""
        assert self.lops_init is not None
        fix = None
        if lops is not None and lops.get("x") is not None and lops.get("y") is not None:
            fix = (float(lops["x"]), float(lops["y"]))
        found = self.lops_init.step(stamp, moving, s, omega, fix)
        if found is None or not self.config["filter"]["enabled"]:
            return
        pose = (found.x_mm, found.y_mm, found.heading)
        self.ekf = PoseEKF(self.ekf_params, pose)
        self.ekf.set_pose(pose, found.sigma_mm, found.sigma_deg)
        self.lops_init = None
        self.message(
            "I",
            stamp,
            f"position initialised by LOPS: {pose[0]:.0f} {pose[1]:.0f} mm, {math.degrees(pose[2]):.1f}° "
            f"(± {found.sigma_mm:.0f} mm, ± {found.sigma_deg:.1f}°) after a {found.drive_mm:.0f} mm drive",
        )

    def _apply_events(self, generation: int, stamp: int) -> None:
        with self._events_lock:
            due = [e for e in self._events if e[0] <= generation]
            self._events = [e for e in self._events if e[0] > generation]
        for _, kind, payload in due:
            if kind == "set_pose":
                pose = (payload["x"], payload["y"], payload["psi"])
                self.dead_reckoning = pose
                self.lops_init = None  # a pose given: nothing to initialise
                if self.gyro_heading is not None:
                    self.gyro_heading = pose[2]
                if self.ekf is None and self.config["filter"]["enabled"]:
                    self.ekf = PoseEKF(self.ekf_params, pose)
                elif self.ekf is not None:
                    self.ekf.set_pose(pose, payload.get("sigma_mm", 10.0), payload.get("sigma_deg", 1.0))
                self.message(
                    "I", stamp, f"pose set to {pose[0]:.0f} {pose[1]:.0f} {math.degrees(pose[2]):.1f}°"
                )
            elif kind == "map_wall" and self.config["walls"]["mode"] == "exploration":
                # (in Darmstadt mode the wall file is the truth; the robot's own map is not mixed in)
                self.known_walls.append(
                    KnownWall.segment(
                        payload["x1"], payload["y1"], payload["x2"], payload["y2"], len(self.known_walls)
                    )
                )
                if self.pending_travel and self.ekf is not None:
                    self._retry_pending_travel(self.known_walls[-1], stamp)

    def process_synchronised(
        self,
        generation: int,
        stamp: int,
        data: dict[str, dict[str, Any]],
        counts: dict[str, int] | None = None,
    ) -> None:
        """The filter step on one synchronised record (online, and replay from synchronised data)."""
        self._apply_events(generation, stamp)
        dt_s = (stamp - self.last_sync_ms) / 1000.0 if self.last_sync_ms is not None else 0.0
        odo = data.get("odometry")
        if self.dead_reckoning is None and odo is not None and "motor" in odo:
            x, y, cdeg = odo["motor"]
            self._initialise((float(x), float(y), wrap(-math.radians(cdeg / 100.0))))
        use = {name: s["filter"] and s.get("synchronise", True) for name, s in self.sensors.items()}
        omega = 0.0
        if odo is not None:
            s, omega = step_motion(odo["dl"], odo["dr"], self.odometry)
        if odo is not None and self.dead_reckoning is not None:
            x, y, psi = advance(self.dead_reckoning, s, omega)
            self.dead_reckoning = (x, y, wrap(psi))
        if self.lops_init is not None and odo is not None:
            self._initialise_by_lops(stamp, odo["dl"] != 0 or odo["dr"] != 0, s, omega, data.get("lops"))
        gyro = data.get("gyro")
        if gyro is not None and self.gyro_heading is None and self.dead_reckoning is not None:
            self.gyro_heading = self.dead_reckoning[2] - float(gyro["turn"])  # its first turn was counted
        if gyro is not None and self.gyro_heading is not None:
            self.gyro_heading = wrap(self.gyro_heading + float(gyro["turn"]))
        wall_results: list[list[int]] = []
        wall_fix: dict[str, Any] | None = None
        if self.ekf is not None:
            if odo is not None and use.get("odometry"):
                travel = (
                    self._correlator_travel(data.get("correlator"), omega, dt_s)
                    if use.get("correlator")
                    else None
                )
                if self.ekf.predict(odo["dl"], odo["dr"], dt_s, travel) is False:
                    self.message("W", stamp, f"correlator rejected by the gate (NIS {self.ekf.last_nis:.1f})")
            compass = data.get("compass")
            turn_rate = abs(math.degrees(omega)) / dt_s if odo is not None and dt_s > 0 else 0.0
            if gyro is not None and use.get("gyro"):
                self._correct_gyro(gyro, turn_rate, stamp)
            if compass is not None and use.get("compass"):
                if turn_rate > self.config["filter"]["compass"]["max_turn_rate_deg_s"]:
                    self.compass_skipped_turning += 1  # the reading lags and the motors disturb it
                elif not self.ekf.correct_heading(compass["heading"]):
                    self.message("W", stamp, f"compass rejected by the gate (NIS {self.ekf.last_nis:.1f})")
            lops = data.get("lops")
            if lops is not None and use.get("lops"):
                self._correct_lops(lops, stamp)
            sonar = data.get("sonar")
            if sonar is not None and use.get("sonar"):
                reference = self.ekf.pose  # the seed's reference: the pose the walls were fitted at
                for wall in sonar.get("walls", []):
                    wall_results.append(self._correct_wall(wall, stamp))
                wall_fix = self._wall_fix(reference, sonar.get("walls", []), wall_results)
                for travel in sonar.get("travel", []):
                    self._correct_travel(travel, stamp)
                ahead = self.config["walls"]["ahead"]
                if ahead["enabled"] and turn_rate <= ahead["max_turn_rate_deg_s"]:
                    self._correct_ahead(sonar, stamp)
            for sensor in self.registry:  # the sensors that bring their own correction
                record = data.get(sensor.name)
                if sensor.fuse is not None and record is not None and use.get(sensor.name):
                    sensor.fuse(self, record, stamp)
        self._store_positions(stamp, data, wall_results, wall_fix)
        self.last_sync_ms = stamp
        self.syncs += 1
        if self.data_log is not None:
            period = round(dt_s * 1000)
            self.data_log.write(
                stamp, "S", "S", {"gen": generation, "period_ms": period, "counts": counts or {}}
            )

    def _store_positions(
        self,
        stamp: int,
        data: dict[str, dict[str, Any]],
        walls: list[list[int]],
        wall_fix: dict[str, Any] | None = None,
    ) -> None:
        log = self.data_log
        store: dict[str, dict[str, Any]] = {}
        for sensor in self.registry:  # the sensors' own: dead reckoning, compass, gyro, truth, LOPS
            if sensor.position is None or not self._computes_position(sensor.name):
                continue
            position = sensor.position(self, data.get(sensor.name))
            if position is not None:
                store[sensor.letter] = position
        if self.ekf is not None:
            x, y, psi = self.ekf.pose
            sx, sy, spsi = self.ekf.sigmas()
            store["K"] = {
                "x": x,
                "y": y,
                "psi": psi,
                "valid": list(self.ekf.validity()),
                "sigma": [sx, sy, spsi],
                "glide": self.ekf.glide,
                "compass_offset": self.ekf.compass_offset,
                "step_scale": self.ekf.step_scale,
                "step_scale_mean": self.ekf.step_scale_mean,
                "step_scale_mean_sigma": self.ekf.step_scale_mean_sigma,
                "walls": walls,
            }
        if wall_fix is not None and self._computes_position("sonar"):
            store["W"] = wall_fix  # one coordinate and the heading, the other invalid (seed §6.2.4)
        for letter, position in store.items():
            position["stamp_ms"] = stamp
            self.positions[letter] = position
            owner = sensor_of_letter(letter)  # None: the filter's, always logged
            if log is not None and (owner is None or self.sensors.get(owner.name, {}).get("log_position")):
                log.write(stamp, letter, "P", {k: v for k, v in position.items() if k != "stamp_ms"})

    def _computes_position(self, name: str) -> bool:
        """Whether the sensor ``name`` puts its own position into the store (seed [Sensors]:
        Position); one not used says yes, as before the switch (the dead reckoning's)."""
        return bool(self.sensors.get(name, {}).get("position", True))

    # ---------------------------------------------------------------------------------------
    # results

    def pose(self) -> LocalizedPose:
        """The best pose: the filter's if it runs, else dead reckoning, else none."""
        stamp = self.last_sync_ms or 0
        if self.ekf is not None:
            x, y, psi = self.ekf.pose
            vx, vy, vpsi = self.ekf.validity()
            return LocalizedPose(x, y, psi, vx, vy, vpsi, "ekf", stamp, self.ekf.sigmas())
        if self.dead_reckoning is not None:
            x, y, psi = self.dead_reckoning
            return LocalizedPose(x, y, psi, True, True, True, "odometry", stamp)
        return LocalizedPose(0.0, 0.0, 0.0, False, False, False, "none", stamp)

    def report(self) -> dict[str, Any]:
        """Counters for tools and tests (plain values)."""
        out: dict[str, Any] = {
            "syncs": self.syncs,
            "last_sync_ms": self.last_sync_ms,
            "timing": {name: self.timing[name].as_dict() for name in self.sensors},
            "walls_associated": self.walls_associated,
            "walls_unassociated": self.walls_unassociated,
            "walls_past_end": self.walls_past_end,
            "walls_fitted": self.detector.fitted if self.detector else 0,
            "compass_skipped": self.synchronisers["compass"].skipped,
            "compass_skipped_turning": self.compass_skipped_turning,
            "compass_skipped_settling": self.synchronisers["compass"].settling,
            "gyro_skipped": self.synchronisers["gyro"].skipped,
            "gyro_skipped_turning": self.gyro_skipped_turning,
            "gyro_relearned": self.gyro_relearned,
            "correlator_skipped": self.synchronisers["correlator"].skipped,
            "correlator_skipped_turning": self.correlator_skipped_turning,
            "travel": dict(self.travel),
            "ahead": dict(self.ahead),
            "grid_skipped": self.trigger.skipped,
        }
        if self.ekf is not None:
            out["gates"] = self.ekf.gates.as_dict()
            out["glide"] = self.ekf.glide
            out["step_scale"] = self.ekf.step_scale
            out["step_scale_mean"] = self.ekf.step_scale_mean
            out["step_scale_mean_sigma"] = self.ekf.step_scale_mean_sigma
            out["compass_offset_deg"] = math.degrees(self.ekf.compass_offset)
        pose = self.pose()
        out["pose"] = {
            "x_mm": pose.x_mm,
            "y_mm": pose.y_mm,
            "heading_deg": math.degrees(pose.heading),
            "valid": [pose.valid_x, pose.valid_y, pose.valid_heading],
            "source": pose.source,
        }
        return out

    def close(self) -> None:
        self.message("I", self.last_sync_ms or 0, f"localisation stopped after {self.syncs} synchronisations")
        for log in (self.data_log, self.error_log):
            if log is not None:
                log.close()


def open_logs(
    config: dict[str, Any],
    directory: str | Path | None = None,
    meta: dict[str, Any] | None = None,
    on_failure: Callable[[str], None] | None = None,
) -> tuple[DataLog | None, ErrorLog | None]:
    """The data and error logs named by the config (``{start}`` = the start time); or (None, None).
    No error log when ``logs.error_log`` is off (the seed's Fehlerlog no); it keeps the classes
    ``logs.debug_level`` says. ``on_failure``: a log that cannot be written (a full disk) says so
    there and ends, whole."""
    logs = config["logs"]
    if not logs["enabled"]:
        return None, None
    start = time.strftime("%Y%m%d-%H%M%S")
    base = Path(directory if directory is not None else logs["directory"])
    data = DataLog(base / logs["data"].format(start=start), start, config, meta, on_failure=on_failure)
    errors = None
    if logs.get("error_log", True):
        level = logs.get("debug_level", 4 if logs.get("debug") else 3)
        errors = ErrorLog(
            base / logs["errors"].format(start=start), start, on_failure=on_failure, level=level
        )
    return data, errors


# =============================================================================================
# the on-ring component


class Localizer:
    """The synchronisation + EKF as a component of a module program (see the module docstring)."""

    def __init__(
        self,
        os: Any,
        config: str | Path | dict | None = None,
        *,
        log_dir: str | Path | None = None,
        truth: Any = None,
        on_log_failure: Callable[[str], None] | None = None,
    ) -> None:
        if config is None:
            from modules.localization.config import default_config_path

            path = default_config_path()
            config = path if path.exists() else None
        import os as _os

        self.os = os
        self.config = with_body(load_config(config), algorithm("body"))
        # $TOKENRING_LOG_DIR overrides the config's logs.directory (tests, benches, `tokenring up`)
        self.log_dir = log_dir if log_dir is not None else _os.environ.get("TOKENRING_LOG_DIR") or None
        self.truth_feed = truth  # the world's ground truth for the logs (copro's hardware), or None
        self.core: LocalizationCore | None = None
        self.buffers: dict[str, Any] = {}
        #: per sensor read from a channel: the field numbering its samples, the fields taken
        self.channel_fields: dict[str, tuple[str | None, tuple[str, ...]]] = {}
        self.last_seen: dict[str, tuple[Any, ...]] = {}
        self._truth_sub: Any = None
        self._lops_sub: Any = None
        #: a log that could not be written (a full disk): its one line each; told to ``on_log_failure``
        self.log_failures: list[str] = []
        self.on_log_failure = on_log_failure

    def setup(self) -> None:
        """Open the logs, build the core and register the data channels the config uses."""
        ring = getattr(getattr(self.os, "transport", None), "ring", None)
        data_log, error_log = open_logs(
            self.config,
            self.log_dir,
            {"node": getattr(self.os, "name", "?"), "ring": ring},
            on_failure=self._log_failed,
        )
        self.core = LocalizationCore(self.config, data_log=data_log, error_log=error_log)
        for sensor in registered():
            if sensor.channel is not None and sensor.name in self.core.sensors:
                self.buffers[sensor.name] = self.os.subscribe(sensor.channel)
                self.channel_fields[sensor.name] = (sensor.seq_field, sensor.value_fields)
        if self.truth_feed is not None and "truth" in self.core.sensors:
            self._subscribe_truth()
        if "lops" in self.core.sensors and hasattr(self.truth_feed, "subscribe_lops"):
            self._lops_sub = self.truth_feed.subscribe_lops(self.feed_lops, self.lops_message)

    def _log_failed(self, line: str) -> None:
        """A log that cannot be written ends whole; one line says so and the localisation goes on."""
        self.log_failures.append(line)
        logger.error("%s; the localisation goes on without it", line)
        if self.on_log_failure is not None:
            self.on_log_failure(line)

    def feed_lops(self, stamp_ms: int, values: dict[str, Any]) -> None:
        """One LOPS data packet as copro's WLAN receiver took it (stamped on arrival)."""
        if self.core is not None:
            self.core.feed(Sample("lops", stamp_ms, values))

    def lops_message(self, stamp_ms: int, letter: str, text: str) -> None:
        """lopscpp's message, to the error log (seed §6.2.5: "Fehlermeldungen ... weitergeleitet")."""
        if self.core is not None:
            self.core.message(letter, stamp_ms, text)

    def _subscribe_truth(self) -> None:
        self._truth_sub = self.truth_feed.subscribe(self.feed_truth)

    def feed_truth(self, stamp_ms: int, x: float, y: float, theta: float) -> None:
        """The world's ground truth (mm, rad CCW) for the logs (source ``T``); never fused."""
        if self.core is not None:
            self.core.feed(Sample("truth", stamp_ms, {"x": x, "y": y, "theta": theta}))

    def step(self) -> SyncResult | None:
        """Take new samples from the token's data channels, then synchronise if triggered."""
        core = self.core
        if core is None:
            raise RuntimeError("Localizer.setup() was not called")
        try:
            return self._step(core)
        except Exception as exc:  # the seed's class F: logged where the run can be read back
            core.message("F", core.last_sync_ms or 0, f"localisation failed: {type(exc).__name__}: {exc}")
            raise

    def _step(self, core: LocalizationCore) -> SyncResult | None:
        for sensor, buffer in self.buffers.items():
            if not buffer.published:
                continue  # nothing copied out of the token yet, or only its zeros before the owner's first store
            values = buffer.read()
            seq_field, value_fields = self.channel_fields[sensor]
            seq = values.get(seq_field) if seq_field else None
            key = (values["stamp_ms"], seq)
            if self.last_seen.get(sensor) == key:
                continue
            self.last_seen[sensor] = key
            if value_fields:
                picked = {f: values[f] for f in value_fields if f in values}
            else:  # all the channel has but its stamp and sample number
                picked = {f: v for f, v in values.items() if f not in ("stamp_ms", seq_field)}
            core.feed(Sample(sensor, int(values["stamp_ms"]), picked, seq))
        return core.maybe_sync(self.os.counter)

    def pose(self) -> LocalizedPose:
        """The fused pose (EKF), else dead reckoning; see :class:`LocalizedPose`."""
        if self.core is None:
            return LocalizedPose(0.0, 0.0, 0.0, False, False, False, "none", 0)
        return self.core.pose()

    def copro_fields(self) -> dict[str, int]:
        """The ``pose_*`` fields of copro.data (wire units: mm, 1/100 degree clockwise)."""
        from modules.units import rad_ccw_to_cdeg_cw

        pose = self.pose()
        clamp = 2**31 - 1
        return {
            "pose_x_mm": max(-clamp, min(clamp, round(pose.x_mm))),
            "pose_y_mm": max(-clamp, min(clamp, round(pose.y_mm))),
            "pose_angle_cdeg": rad_ccw_to_cdeg_cw(pose.heading),
            "pose_valid": pose.valid_bits,
            "pose_source": SOURCE_CODES[pose.source],
            "pose_stamp_ms": pose.stamp_ms & 0xFFFFFFFF,
        }

    def set_pose(
        self, x_mm: float, y_mm: float, heading: float, sigma_mm: float = 10.0, sigma_deg: float = 1.0
    ) -> None:
        """Re-initialise the pose at the next synchronisation (like SET_GLOBAL_POSITION)."""
        if self.core is not None:
            self.core.event(
                "set_pose",
                x=float(x_mm),
                y=float(y_mm),
                psi=float(heading),
                sigma_mm=sigma_mm,
                sigma_deg=sigma_deg,
            )

    def add_map_wall(self, x1: float, y1: float, x2: float, y2: float) -> None:
        """Exploration mode: a wall of the robot's own map (mm) becomes a known wall."""
        if self.core is not None:
            self.core.event("map_wall", x1=float(x1), y1=float(y1), x2=float(x2), y2=float(y2))

    def report(self) -> dict[str, Any]:
        return self.core.report() if self.core is not None else {}

    @property
    def log_path(self) -> Path | None:
        return self.core.data_log.path if self.core is not None and self.core.data_log is not None else None

    def close(self) -> None:
        for sub in (self._truth_sub, self._lops_sub):
            if sub is not None:
                with contextlib.suppress(Exception):
                    sub.undeclare()
        self._truth_sub = self._lops_sub = None
        if self.core is not None:
            self.core.close()
