"""ROBCOPRO, the coprocessor (seed §4.3.4): side hypotheses and vector generation.

Every sonar sweep: ``observe_side`` for both sides (WALL / OBSTACLE / CORNER / NONE with
confidence and distance area, published on ``copro.data``). Only on forward moves, with
scanning on (START_SCAN / STOP_SCAN) and after more than 1 cm driven, vectors are generated
and sent to map — by the seed's edge following (SET_METHOD 0) or by ours (SET_METHOD 1, the
default): robust straight runs of global points, collinear merge and corner closing (held-back
vectors go out on FLUSH).

The pose: the filtered pose of :class:`modules.localization.localizer.Localizer` when that module
exists (hosted here, stepped every token visit), else dead reckoning from ``motor.data``; both
are published in the ``pose_*`` fields (source 2 = EKF, 1 = dead reckoning), and the filter's
standard deviations in ``sigma_*`` (0 without a filter) so tools can draw its uncertainty.

Beside the token, the localisation's live state as the seed's screen showed it (seed 000 §6.6:
:func:`modules.localization.liveview.snapshot`, at most five times a second) and its messages
(§6.8.3: each as it is said, and the backlog on request, for a screen opened later) go out on the
keys ``robot/localization/*`` (:class:`LivePublisher`); without a localizer, nothing.

Seed mode (``--algorithms copro=seed``, seed §4.3.4): the seed's edge follower on the newest
dead-reckoned pose from ``motor.data`` alone; no localizer runs, so no vector becomes a map wall
for it, and nothing of ours (collinear merge, corner closing) touches the vectors.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os as _os
import queue
import time
from collections.abc import Callable
from typing import Any

import msgpack

from modules.mapping.vectorgen import OUR_METHOD, SEED_METHOD, PoseHistory, Vector, Vectorizer, default_layout
from modules.mapping.vectormap import vector_to_wire
from modules.units import pose_from_wire, pose_to_wire
from modules.variants import algorithm
from tokenring import UserProgram
from tokenring.runtime import current as current_runtime

log = logging.getLogger("tokenring.copro")

SEED, OURS = SEED_METHOD, OUR_METHOD
POSE_NONE, POSE_DEAD_RECKONING, POSE_EKF = 0, 1, 2
FLUSHED = object()  # in the vector queue: every vector before it has been delivered
MIN_DRIVEN_MM = 10  # the seed: vectors only after more than 1 cm driven
LIVE_PERIOD_S = 0.2  # the localisation's live state at most five times a second


#: the localizer's settings while exploring an unknown room: start where the motor was put down,
#: correct against the long walls of the robot's own map (handed over as they are found), no log
#: files. Without known walls a compass offset is unobservable (it only soaked up the errors of
#: early map walls and kept them), and on straight moves the tracks cannot turn the robot: the
#: heading then holds through a magnetic anomaly instead of following the compass into it. The
#: step scale is measured by the front and rear sonar on straight drives (the map's own walls
#: cannot see it: they were drawn with it); it is the floor's, so it drifts little between moves.
EXPLORATION_CONFIG: dict[str, Any] = {
    "filter": {
        "initial_pose": "motor",
        "estimate": ["glide", "step_scale"],
        "noise": {"rotation_rad_per_mm": 0.00002, "step_scale_per_move": 0.001},
        "initial": {"step_scale_sigma": 0.01},
        # out to 1.4 m: the late echo (walls.sonar_late) is taken off each range; on a wall the
        # own map lacks, only a precise fit, and not one far below the filter's (cos φ reads low)
        "travel": {
            "enabled": True,
            "max_range_mm": 1400.0,
            "unknown_wall_bound": True,
            "unknown_wall_bound_sigma": 2.0,
            "unknown_wall_max_sigma": 0.006,
        },
        "compass": {"settle_ms": 400},
    },
    # own-map walls: every fit used, as when this was tuned (repeat_after_mm was measured on
    # the Darmstadt and generated drives only). The sonar model is the localisation's (issue 21,
    # config/localization.yaml): ranges as tangents with the late echo taken off, the error a
    # fit's points share, side lines of 220 mm at least
    "walls": {
        "mode": "exploration",
        "association": {"min_wall_length_mm": 1000.0},
        "repeat_after_mm": 0.0,
        "range_model": "tangent",
        "shared_sigma_mm": 8.0,
        "min_span_side_mm": 220.0,
    },
    "logs": {"enabled": False},
}


def open_localizer(os: Any, truth: Any = None) -> Any | None:
    """The EKF localizer (modules.localization.localizer), configured for exploration; None without it.

    ``$TOKENRING_LOCALIZER_CONFIG`` names another configuration file; ``$TOKENRING_LOCALIZER=off``
    maps on dead reckoning alone (the benchmark compares both). ``$TOKENRING_SENSORS`` (``up
    --sensors``) lays its set's sensors beneath the configuration, whose keys win."""
    if _os.environ.get("TOKENRING_LOCALIZER", "").lower() in ("off", "0", "no"):
        return None
    try:
        from modules.localization.config import load_config, sensor_set_layer
        from modules.localization.localizer import Localizer
    except ImportError:
        return None
    config: Any = _os.environ.get("TOKENRING_LOCALIZER_CONFIG") or EXPLORATION_CONFIG
    try:
        receivers = _os.environ.get("TOKENRING_LOPS_RECEIVERS")
        under = sensor_set_layer(
            _os.environ.get("TOKENRING_SENSORS"), json.loads(receivers) if receivers else None
        )
        if under:
            config = load_config(config, under=under)
        localizer = Localizer(os, config, truth=truth, on_log_failure=incomplete_flag(truth, os.name, "logs"))
        localizer.setup()
    except Exception as exc:  # the map still works on dead reckoning
        log.error("localizer unavailable, using dead reckoning: %s", exc)
        return None
    return localizer


def incomplete_flag(hardware: Any, module: str, what: str) -> Callable[[str], None] | None:
    """What tells ``tokenring up`` that this module's run is not whole (a log cut short by a full
    disk): a liveliness token ``robot/incomplete/<module>/<what>`` on the hardware's Zenoh
    session, held while the node runs (``up`` then exits 1). None without a session."""
    session, ring = getattr(hardware, "session", None), getattr(hardware, "ring", None)
    if session is None or ring is None:
        return None
    from modules.description import keys as robot_keys

    held: list[Any] = []

    def flag(_line: str) -> None:
        if held:
            return
        try:
            held.append(session.liveliness().declare_token(robot_keys.incomplete(ring, module, what)))
        except Exception as exc:  # a closing session: the node's own line still says what was lost
            log.warning("could not tell the launcher that the %s are incomplete: %s", what, exc)

    return flag


class LivePublisher:
    """The localisation's live state and messages beside the ring, never in the token (keys
    :func:`modules.description.keys.localization`): :meth:`step`, on the program's thread after
    each step of the localizer, watches the synchronisation's period and, at most every
    ``period_s``, takes a snapshot; a thread of its own puts it and each message as the core says
    it (a put that stalls holds up only that thread, never a token visit); a queryable answers
    the backlog (seed §6.8.3: messages said before a screen opened are shown once it does).
    ``run`` tells this copro's messages from a restarted one's (their ``n`` starts again)."""

    def __init__(self, session: Any, ring: str, core: Any, period_s: float = LIVE_PERIOD_S) -> None:
        from modules.description import keys as robot_keys
        from modules.localization.liveview import SyncPeriods

        self.core = core
        self.period_s = period_s
        self.run = f"{_os.getpid()}-{time.time_ns()}"
        self.periods = SyncPeriods()
        self.stats = {"states": 0, "messages": 0, "dropped": 0}
        self._state: dict[str, Any] | None = None
        self.rt = current_runtime()  # the clock, queue, events and thread
        self._messages: queue.Queue[dict[str, Any]] = self.rt.queue(maxsize=1000)
        self._wake = self.rt.event()
        self._stopping = self.rt.event()
        self._due = 0.0
        self._declared: list[Any] = []
        self._state_pub = session.declare_publisher(robot_keys.localization(ring, "state"))
        self._declared.append(self._state_pub)
        self._message_pub = session.declare_publisher(robot_keys.localization(ring, "message"))
        self._declared.append(self._message_pub)
        self._declared.append(
            session.declare_queryable(robot_keys.localization(ring, "messages"), self._answer)
        )
        core.message_listeners.append(self._on_message)
        self._thread = self.rt.spawn(self._run, "copro-live")

    def step(self) -> None:
        """After a step of the localizer, on its thread (the snapshot reads the core's state)."""
        from modules.localization.liveview import snapshot

        self.periods.observe(self.core)
        now = self.rt.monotonic()
        if now < self._due:
            return
        self._due = now + self.period_s
        self._state = snapshot(self.core, self.periods)
        self._wake.set()

    def _on_message(self, entry: dict[str, Any]) -> None:
        try:
            self._messages.put_nowait({"run": self.run, **entry})
        except queue.Full:  # nobody takes them (a stalled put): the backlog still has them
            self.stats["dropped"] += 1
        self._wake.set()

    def _answer(self, query: Any) -> None:
        try:
            backlog = list(self.core.messages)  # copied in one go: no Python code runs meanwhile
            reply = {"ok": True, "result": {"run": self.run, "messages": backlog}}
            query.reply(query.key_expr, msgpack.packb(reply))
        except Exception as exc:  # a closing session; the asker times out
            log.warning("the localisation's messages could not be answered: %s", exc)

    def _run(self) -> None:
        while not self._stopping.is_set():
            self._wake.wait(1.0)
            self._wake.clear()
            try:
                while True:
                    try:
                        entry = self._messages.get_nowait()
                    except queue.Empty:
                        break
                    self._message_pub.put(msgpack.packb(entry))
                    self.stats["messages"] += 1
                state, self._state = self._state, None
                if state is not None:
                    self._state_pub.put(msgpack.packb(state))
                    self.stats["states"] += 1
            except Exception as exc:  # a closing session
                if not self._stopping.is_set():
                    log.warning("the localisation's live state could not be published: %s", exc)

    def close(self) -> None:
        with contextlib.suppress(ValueError):
            self.core.message_listeners.remove(self._on_message)
        self._stopping.set()
        self._wake.set()
        self._thread.join(timeout=2.0)
        for item in reversed(self._declared):
            with contextlib.suppress(Exception):
                item.undeclare()
        self._declared.clear()


def open_live(hardware: Any, localizer: Any) -> LivePublisher | None:
    """The localizer's :class:`LivePublisher` on the hardware's Zenoh session; None without a
    localizer (seed mode, ``$TOKENRING_LOCALIZER=off``) or a session."""
    core = getattr(localizer, "core", None)
    session, ring = getattr(hardware, "session", None), getattr(hardware, "ring", None)
    if core is None or session is None or ring is None:
        return None
    try:
        return LivePublisher(session, ring, core)
    except Exception as exc:  # the localisation runs on unseen
        log.warning("the localisation's live state will not be published: %s", exc)
        return None


def localizer_pose(
    localizer: Any,
) -> tuple[tuple[float, float, float], int, int, int | None, tuple[float, float, float] | None] | None:
    """(pose, validity bits, source, stamp, sigmas) from the localizer's ``pose()``, whatever its
    shape; ``sigmas`` (x mm, y mm, heading rad) is the filter's, None if it gives none."""
    got = localizer.pose()
    if got is None:
        return None
    if isinstance(got, dict):
        x, y, th = got["x_mm"], got["y_mm"], got.get("heading_rad", got.get("heading"))
        valid, source = got.get("valid", 7), got.get("source", POSE_EKF)
    elif isinstance(got, tuple | list):
        x, y, th, *rest = got
        valid = rest[0] if rest else 7
        source = rest[1] if len(rest) > 1 else POSE_EKF
    else:
        x, y = got.x_mm, got.y_mm
        th = getattr(got, "heading_rad", getattr(got, "heading", 0.0))
        valid = getattr(got, "valid_bits", getattr(got, "valid", 7))
        source = getattr(got, "source", POSE_EKF)
        if source == "none":
            return None
    if isinstance(valid, tuple | list):
        valid = sum(1 << i for i, v in enumerate(valid[:3]) if v)
    if isinstance(source, str):
        source = POSE_EKF if source.lower() in ("ekf", "filter", "fused") else POSE_DEAD_RECKONING
    stamp = got.get("stamp_ms") if isinstance(got, dict) else getattr(got, "stamp_ms", None)
    sigmas = got.get("sigmas") if isinstance(got, dict) else getattr(got, "sigmas", None)
    return (float(x), float(y), float(th)), int(valid), int(source), stamp, sigmas


def wire_sigmas(sigmas: tuple[float, float, float] | None) -> dict[str, int]:
    """copro.data's ``sigma_*`` fields: mm and 1/100 degree, 0 = not known, saturating at 65535."""
    if sigmas is None or not all(math.isfinite(v) for v in sigmas):
        return {"sigma_x_mm": 0, "sigma_y_mm": 0, "sigma_angle_cdeg": 0}
    sx, sy, spsi = sigmas

    def clamp(value: float) -> int:
        return max(1, min(0xFFFF, round(value)))

    return {
        "sigma_x_mm": clamp(sx),
        "sigma_y_mm": clamp(sy),
        "sigma_angle_cdeg": clamp(math.degrees(spsi) * 100.0),
    }


class Program(UserProgram):
    module = "copro"

    def setup(self) -> None:
        os = self.os
        enums = os.protocol.enums
        self.forward = enums["direction"]["FORWARD"]
        self.data = os.publish()
        self.sonar = os.subscribe("sonar.data")
        self.motor = os.subscribe("motor.data")
        os.set_own_input_id()
        self.layout = default_layout(algorithm("body"))
        # seed mode (seed §4.3.4): the 2001 copro, its edge follower on the motor's dead
        # reckoning alone: no filter, no walls handed to one, no post-processing of vectors
        self.seed_mode = algorithm("copro") == "seed"
        self.method = int(_os.environ.get("TOKENRING_COPRO_METHOD", SEED if self.seed_mode else OURS))
        self.scanning = False
        self.history = PoseHistory()
        self.rt = current_runtime()  # the queue and thread: the process's, or a simulation's
        self.outgoing: queue.Queue[Vector | object | None] = self.rt.queue()
        self.stats = {
            "vectors_sent": 0,
            "vectors_refused": 0,
            "sweeps": 0,
            "sweeps_missed": 0,
            "flushes_done": 0,
        }
        self.last_sweep: int | None = None
        self.pose_source = POSE_NONE
        self.pose_sigmas: tuple[float, float, float] | None = None
        self._make_generators()
        self.localizer = None if self.seed_mode else open_localizer(os, self.hw)
        self.live = open_live(self.hw, self.localizer)
        self.sender = self.rt.spawn(self._send_vectors, "copro-vectors")

    def _make_generators(self) -> None:
        self.vectorizer = Vectorizer(self.layout, self.method, self._emit)

    def _emit(self, vector: Vector) -> None:
        """A finished vector: to the map, and to the localizer as a wall of the robot's own map."""
        self.outgoing.put(vector)
        if getattr(self, "localizer", None) is not None:
            self.localizer.add_map_wall(*vector)

    # -- the loop ---------------------------------------------------------------------------
    def run(self) -> None:
        while self.running:
            self.os.wait_visit(0.2)
            self._handle_commands()
            pose = self._update_pose()
            if self.live is not None and self.localizer is not None:
                self.live.step()
            sonar = self.sonar.read()
            if self.sonar.visits and sonar["sweep"] != self.last_sweep:
                if self.last_sweep is not None and (sonar["sweep"] - self.last_sweep) & 0xFFFF > 1:
                    self.stats["sweeps_missed"] += ((sonar["sweep"] - self.last_sweep) & 0xFFFF) - 1
                self.last_sweep = sonar["sweep"]
                self.stats["sweeps"] += 1
                self.process_sweep(sonar, self.motor.read(), pose)
            self._publish()

    def _handle_commands(self) -> None:
        while True:
            command = self.os.receive_command(timeout=0)
            if command is None:
                return
            self.handle_command(command.name, command.args)

    def handle_command(self, name: str, args: dict[str, Any]) -> None:
        if name == "START_SCAN":
            self.scanning = True
        elif name == "STOP_SCAN":
            self.scanning = False
            self._end_scan()
        elif name == "SET_METHOD":
            self._end_scan()
            self.flush()
            self.method = SEED if int(args.get("method", OURS)) == SEED else OURS
            self._make_generators()
        elif name == "FLUSH":
            self._end_scan()
            self.flush()
            self.outgoing.put(FLUSHED)  # counted once the vectors queued before it are delivered
        elif name == "ERROR":
            self.stats["vectors_refused"] += 1
            log.warning("map refused a vector: %s", args)

    def _end_scan(self) -> None:
        self.vectorizer.end_scan()

    def flush(self) -> None:
        self.vectorizer.flush()

    def _update_pose(self) -> tuple[float, float, float] | None:
        """Record dead reckoning; return the best pose now (EKF if running)."""
        motor = self.motor.read()
        if self.motor.published:
            self.history.add(
                motor["stamp_ms"], pose_from_wire(motor["x_mm"], motor["y_mm"], motor["angle_cdeg"])
            )
        if self.localizer is not None:
            try:
                self.localizer.step()
                got = localizer_pose(self.localizer)
            except Exception as exc:
                log.error("localizer failed, back to dead reckoning: %s", exc)
                self.localizer = None
                got = None
            if got is not None:
                pose, valid, source, stamp, sigmas = got
                self.pose_valid, self.pose_source = valid, source
                self.pose_sigmas = sigmas if source == POSE_EKF else None
                self.pose_stamp = stamp if stamp is not None else motor["stamp_ms"]
                self.best_pose = pose
                return pose
        pose = self.history.latest()
        if pose is not None:
            self.pose_valid, self.pose_source, self.pose_stamp = 7, POSE_DEAD_RECKONING, motor["stamp_ms"]
            self.pose_sigmas = None
            self.best_pose = pose
        return pose

    def process_sweep(self, sonar: dict[str, Any], motor: dict[str, Any], pose: Any) -> None:
        """One sweep: hypotheses for both sides, then vector generation where it applies."""
        if self.method == OURS:
            pose = self._pose_at(sonar["stamp_ms"], pose)
        elif self.seed_mode:
            # seed §4.3.4: "die aktuelle Position der Motorsteuerung", the newest motor.data pose
            # as this sweep is processed (not interpolated to the sweep's time)
            pose = self.history.latest()
        active = (
            self.scanning
            and motor["direction"] == self.forward
            and motor["distance_mm"] > MIN_DRIVEN_MM
            and pose is not None
        )
        self.vectorizer.sweep(sonar, pose, bool(active))

    def _pose_at(self, stamp_ms: int, pose: Any) -> Any:
        """The best pose at a sweep's time stamp: dead reckoning interpolated there; with the
        filter, its pose moved on by the dead-reckoned motion since the filter's own stamp."""
        at_sweep = self.history.at(stamp_ms)
        if at_sweep is None or pose is None:
            return pose
        if self.pose_source != POSE_EKF:
            return at_sweep
        return self.history.carry(pose, self.pose_stamp, stamp_ms)

    def _publish(self) -> None:
        left, right = self.vectorizer.hypotheses["left"], self.vectorizer.hypotheses["right"]
        fields: dict[str, Any] = {
            "left_contact": left.contact,
            "left_confidence": left.confidence,
            "left_area": left.area,
            "right_contact": right.contact,
            "right_confidence": right.confidence,
            "right_area": right.area,
            "scanning": int(self.scanning),
            "vectors_sent": self.stats["vectors_sent"] & 0xFFFF,
            "flushes_done": self.stats["flushes_done"] & 0xFF,
            "pose_source": self.pose_source,
            **wire_sigmas(self.pose_sigmas),
        }
        if self.pose_source != POSE_NONE:
            x, y, th = self.best_pose
            wire = pose_to_wire(x, y, th)
            fields.update(
                pose_x_mm=max(-(2**31), min(2**31 - 1, wire["x_mm"])),
                pose_y_mm=max(-(2**31), min(2**31 - 1, wire["y_mm"])),
                pose_angle_cdeg=wire["angle_cdeg"],
                pose_valid=self.pose_valid & 0xFF,
                pose_stamp_ms=self.pose_stamp & 0xFFFFFFFF,
            )
        self.data.write(**fields)

    def _send_vectors(self) -> None:
        while self.running:
            try:
                vector = self.outgoing.get(timeout=0.2)
            except queue.Empty:
                continue
            if vector is None:
                break
            if vector is FLUSHED:
                self.stats["flushes_done"] += 1
                continue
            assert isinstance(vector, tuple)
            if self.os.deliver("map", "VECTOR", timeout=5.0, **vector_to_wire(*vector)):
                self.stats["vectors_sent"] += 1
            else:
                log.warning("map did not take a vector within 5 s: %s", vector)

    def teardown(self) -> None:
        self.outgoing.put(None)
        live = getattr(self, "live", None)
        if live is not None:
            live.close()

    def report(self) -> dict[str, Any]:
        return {
            "method": "seed" if self.method == SEED else "ours",
            "scanning": self.scanning,
            "pose_source": self.pose_source,
            "corners_closed": self.vectorizer.corners_closed,
            "merged": self.vectorizer.merged,
            "pending": sum(p.pending is not None for p in self.vectorizer.post.values()),
            "queued": self.outgoing.qsize(),
            **self.stats,
            # the filter's corrections, accepted and rejected per kind (compass, walls, LOPS, ...)
            "gates": (self.localizer.report().get("gates") if self.localizer is not None else None),
            # the live state and messages put beside the ring (None: nothing published)
            "live": dict(live.stats) if (live := getattr(self, "live", None)) is not None else None,
        }
