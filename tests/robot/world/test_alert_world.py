"""ALERT in the simulated world (issue 20; seed 001 §4.3.6): the robot drives into a wall.

The seed's pilot aborts any move when a sonar reads under 4 cm (ALERT) and then accepts only the
opposite direction until the navigator commands it. For that rule to matter the world must let a
sonar read under 4 cm as the robot touches something: the transducers sit on the body's outline.

First the world alone: the simulated robot is driven into a wall at several angles, forward and
in reverse, until the collision body stops it; the pairs facing the wall then read under 4 cm
with the seed's contact method and with ours. Then the whole ring over Zenoh: an action file
``s 600`` points the robot at a wall 30 cm in front of its body. The seed's robot (``--algorithms
seed``) drives on until ALERT aborts the drive near the wall, the lock refuses a drive the other
way, a drive in the allowed direction is taken and releases the lock. Ours never gets there
(issue 57): its pilot stops the drive outside the ALERT area, by the clearance it keeps from
what the sonars showed, refuses a further drive toward the wall and backs away when asked; the
same drive in process (:mod:`modules.sim.drivesim`) stops the same way.

The ring's judge is outside the programs: main.data, motor.data and sonar.data are decoded here
from main's raw token frames as a tap hears them (offsets from protocol.yaml, read with PyYAML,
struct-unpacked), the robot's motion is the world simulator's ground truth. The ALERT bound is
written out from the seed's text. The seed's pilot stops *any* move while *any* sonar reads
ALERT, the escape too (seed pilot_1: "Fahrt auf jeden Fall abbrechen"): its escape is taken and
then stopped again while the sonar still reads ALERT, as the seed's rule says.
"""

from __future__ import annotations

import math
import signal
import struct
import threading
import time
from dataclasses import astuple, dataclass
from typing import Any

import numpy as np
import pytest
import yaml

from modules.description import keys as robot_keys
from modules.description import load_world
from modules.description.robot import FRONT, FRONT_LEFT, FRONT_RIGHT, MAX_STEP_RATE_HZ, REAR
from modules.sensors.sonar import contact_seed_tangent, contact_tangent
from modules.world.sim import Simulator
from tests.support.processes import REPO
from tests.support.ringjudge import Header
from tests.support.ringutil import tap, wait_main_answers, wait_until
from tokenring.host.pclink import PcLink, open_link
from tokenring.transport.session import query

PROTOCOL_YAML = REPO / "protocol.yaml"
SEED_ALERT_BELOW_CM = 4  # seed §4.3.6: "Bereichsunterschreitung von 4cm (dies entspricht dem ALERT-Bereich)"
ROBOT_RADIUS_MM = 190.0  # the world file's collision circle (written below)
WALL_X = 2000.0
START_X = WALL_X - ROBOT_RADIUS_MM - 300.0  # the body's front 30 cm from the wall
ROOM = f"""
name: alert-wall
description: a wall 30 cm in front of the robot's body
start: {{x: {START_X:g}, y: 1000, angle_deg: 0}}
robot_radius_mm: {ROBOT_RADIUS_MM:g}
walls:
  - polygon: [[0, 0], [{WALL_X:g}, 0], [{WALL_X:g}, 2000], [0, 2000]]
"""
SIZES = {"u8": 1, "i8": 1, "u16": 2, "i16": 2, "u32": 4, "i32": 4, "u64": 8, "i64": 8, "f32": 4, "f64": 8}
CODES = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i", "u64": "Q", "i64": "q"}


# -- the world alone: touching a wall reads ALERT -------------------------------------------------

FRONT_PAIRS = (FRONT_LEFT, FRONT, FRONT_RIGHT)
PINGS = 5  # the robot stands at the wall for several sweeps: the pilot sees the typical reading


def touch_and_ping(approach_deg: float, direction: int, seed: int) -> list[list[int]]:
    """Drive the simulated robot (``direction`` +1 forward, -1 reverse) into the empty room's wall
    at x = 4000 mm, its course ``approach_deg`` off the wall's normal, until the collision body
    stops it; then ``PINGS`` envelopes of every pair, read with the seed's contact method and
    ours: per method, per pair, the median reading in cm."""
    sim = Simulator(load_world("empty"), seed=seed)
    course = math.radians(approach_deg)
    sim.set_pose({"x_mm": 3200.0, "y_mm": 1500.0, "theta_rad": course if direction > 0 else course + math.pi})
    for _ in range(2000):
        reply = sim.motor_steps(
            {"left": 20 * direction, "right": 20 * direction, "rate_hz": MAX_STEP_RATE_HZ, "move": 1}
        )
        if reply["blocked"]:
            break
    else:
        raise AssertionError("the robot never reached the wall")
    assert sim.truth()["collisions"] == 1
    readings: dict[str, list[list[int]]] = {"seed": [], "ours": []}
    for _ in range(PINGS):
        envelopes = sim.sonar_ping({"sensors": list(range(8))})["envelopes"]
        samples = [np.frombuffer(e, dtype=np.uint8) for e in envelopes]
        readings["seed"].append([contact_seed_tangent(x) for x in samples])
        readings["ours"].append([contact_tangent(x) for x in samples])
    return [
        [int(np.median([r[pair] for r in readings[method]])) for pair in range(8)]
        for method in ("seed", "ours")
    ]


@pytest.mark.parametrize("approach_deg", [-60, -45, -30, -15, 0, 15, 30, 45, 60])
def test_a_forward_drive_into_a_wall_reads_alert_on_a_front_pair_as_it_touches(approach_deg):
    """Any course up to 60° off the wall's normal (beyond it the robot grazes along the wall): as
    the body touches, a front pair reads under 4 cm — the ALERT area, which the pilot watches on
    the front pairs for a forward move (the seed's pilot on every pair)."""
    for method, medians in zip(("seed", "ours"), touch_and_ping(approach_deg, +1, seed=3), strict=True):
        front = [medians[pair] for pair in FRONT_PAIRS]
        assert min(front) < SEED_ALERT_BELOW_CM, (method, approach_deg, medians)


@pytest.mark.parametrize("approach_deg", [-20, 0, 20])
def test_a_reverse_drive_into_a_wall_reads_alert_on_the_rear_pair_as_it_touches(approach_deg):
    for method, medians in zip(("seed", "ours"), touch_and_ping(approach_deg, -1, seed=4), strict=True):
        assert medians[REAR] < SEED_ALERT_BELOW_CM, (method, approach_deg, medians)


# -- the judge's own reading of the token ----------------------------------------------------------


def channel_layout(node: str) -> dict[str, tuple[int, str, int]]:
    """A data channel's fields as (absolute offset, struct code, count), packed as protocol.yaml
    says: in the order written, from the channel's address, little-endian."""
    doc = yaml.safe_load(PROTOCOL_YAML.read_text())
    data = doc["nodes"][node]["data"]
    offset = int(data["address"])
    out = {}
    for name, spec in data["fields"].items():
        kind = spec["type"] if isinstance(spec, dict) else spec
        count = 1
        if "[" in kind:
            kind, count = kind[: kind.index("[")], int(kind[kind.index("[") + 1 : -1])
        out[name] = (offset, CODES[kind], count)
        offset += SIZES[kind] * count
    return out


def enum(name: str) -> dict[str, int]:
    return yaml.safe_load(PROTOCOL_YAML.read_text())["enums"][name]


DIRECTION = enum("direction")
REASON = enum("abort_reason")
MOTOR_STATE = enum("motor_state")


@dataclass(frozen=True)
class Snapshot:
    """What one token frame says about main, the motor and the sonar."""

    t: float
    abort_reason: int
    alert_lock: int
    navigator: int
    direction: int
    move_seq: int
    motor_state: int
    distances: tuple[int, ...]
    sweep: int


class TokenTimeline:
    """main.data, motor.data and sonar.data as main sent them on, decoded from main's own frames
    on the ring's token keys (one sender's frames arrive in its send order; the token carries
    every channel, so main's frame holds the sonar readings its decision saw). Keeps changes."""

    FIELDS = (
        ("main", "abort_reason"),
        ("main", "alert_lock"),
        ("main", "navigator"),
        ("motor", "direction"),
        ("motor", "move_seq"),
        ("motor", "state"),
        ("sonar", "distances"),
        ("sonar", "sweep"),
    )

    def __init__(self, session: Any, ring: str) -> None:
        doc = yaml.safe_load(PROTOCOL_YAML.read_text())
        self.main_id = int(doc["nodes"]["main"]["id"])
        self.header = Header.from_protocol(PROTOCOL_YAML)
        self.where = [channel_layout(node)[field] for node, field in self.FIELDS]
        self.changes: list[Snapshot] = []
        self._lock = threading.Lock()
        self._sub = session.declare_subscriber(f"tokenring/{ring}/token/*", self._on)

    def _on(self, sample: Any) -> None:
        frame = sample.payload.to_bytes()
        if not self.header.valid(frame) or frame[self.header.sid] != self.main_id:
            return
        values: list[Any] = []
        for offset, code, count in self.where:
            got = struct.unpack_from(f"<{count}{code}", frame, offset)
            values.append(tuple(got) if count > 1 else got[0])
        snap = Snapshot(time.monotonic(), *values)
        with self._lock:
            if not self.changes or astuple(self.changes[-1])[1:] != astuple(snap)[1:]:
                self.changes.append(snap)

    def since(self, t: float) -> list[Snapshot]:
        with self._lock:
            return [s for s in self.changes if s.t >= t]

    def last(self) -> Snapshot | None:
        with self._lock:
            return self.changes[-1] if self.changes else None

    def close(self) -> None:
        self._sub.undeclare()


class TruthTrace:
    """The world's ground truth (``world/state``), sampled in the background."""

    def __init__(self, session: Any, ring: str, interval: float = 0.02) -> None:
        self.session, self.key, self.interval = session, robot_keys.world(ring, "state"), interval
        self.samples: list[tuple[float, dict[str, Any]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="truth-trace", daemon=True)
        self._thread.start()

    def now(self) -> dict[str, Any] | None:
        for _, reply in query(self.session, self.key, timeout=2.0):
            if reply.get("ok"):
                return reply["result"]
        return None

    def _run(self) -> None:
        while not self._stop.is_set():
            truth = self.now()
            if truth is not None:
                self.samples.append((time.monotonic(), truth))
            self._stop.wait(self.interval)

    def since(self, t: float) -> list[dict[str, Any]]:
        return [truth for at, truth in list(self.samples) if at >= t]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)


def front_gap_mm(truth: dict[str, Any]) -> float:
    """How far the body's front is from the wall ahead (the robot faces +X)."""
    return WALL_X - ROBOT_RADIUS_MM - truth["x_mm"]


def run_file(link: PcLink, text: str, timeout: float) -> dict[str, Any]:
    """Hand main an action file and wait (hang guard ``timeout``) until its navigator ended."""
    state = link.request("actions", text=text, name="alert.act", speed_pct=30)
    deadline = time.monotonic() + timeout
    while state.get("running"):
        assert time.monotonic() < deadline, f"the action file {text!r} did not end: {state}"
        time.sleep(0.2)
        state = link.request("state")
    return state


def first(snaps: list[Snapshot], condition: Any, what: str) -> Snapshot:
    for snap in snaps:
        if condition(snap):
            return snap
    raise AssertionError(f"main's frames never showed {what}: {snaps[-5:]}")


def drive_text(direction: int, mm: int) -> str:
    return f"s {mm if direction == DIRECTION['FORWARD'] else -mm}\n"


FORWARD, REVERSE, STOPPED = DIRECTION["FORWARD"], DIRECTION["REVERSE"], DIRECTION["STOPPED"]
OPPOSITE = {FORWARD: REVERSE, REVERSE: FORWARD}


@pytest.mark.slow
@pytest.mark.timeout(900)  # its hang guards: the ring boots, then four action files each up to 300 s
def test_the_seed_robot_driving_into_a_wall_alerts_locks_and_escapes(procs, ring_name, endpoint, tmp_path):
    at_the_wall(procs, ring_name, endpoint, tmp_path, "seed", judge)


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_ours_stops_a_drive_toward_a_wall_outside_the_alert_area(procs, ring_name, endpoint, tmp_path):
    at_the_wall(procs, ring_name, endpoint, tmp_path, "ours", judge_clearance)


def test_ours_stops_the_same_drive_in_process_outside_the_alert_area(tmp_path):
    """The drive of :func:`test_ours_stops_a_drive_toward_a_wall_outside_the_alert_area` without a
    ring: main's action navigator and pilot on one simulated clock stop it the same way."""
    from modules.sim.drivesim import DriveSim, repository_config

    room = tmp_path / "alert-wall.yaml"
    room.write_text(ROOM)
    sim = DriveSim(str(room), 1, "s 600\n", repository_config(str(room)))
    result = sim.drive(max_minutes=5.0)
    truth = result["truth"]  # (t, x, y, theta) rows
    gap = WALL_X - ROBOT_RADIUS_MM - truth[:, 1]
    print(f"[in process] {result['finished']}; the body came within {gap.min():.0f} mm of the wall")
    assert "CLOSE" in result["finished"], result["finished"]
    assert SEED_ALERT_BELOW_CM * 10 < gap.min() < 200.0
    assert sim.robot.collisions == 0


def at_the_wall(
    procs: Any, ring_name: str, endpoint: str, tmp_path: Any, algorithms: str, judged: Any
) -> None:
    """A ring in the room with the wall 30 cm in front of the body, judged by ``judged``."""
    room = tmp_path / "alert-wall.yaml"
    room.write_text(ROOM)
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--world", str(room), "--speed", "4",
        "--bitrate", "max", "--duration", "600", "--algorithms", algorithms,
    )  # fmt: skip
    try:
        with tap(endpoint) as session:
            timeline = TokenTimeline(session, ring_name)
            truth = TruthTrace(session, ring_name)
            try:
                link = open_link(session, ring_name, wait=60.0)

                wait_main_answers(link)
                wait_until(lambda: (s := timeline.last()) and s.sweep > 3, 60, "sonar sweeps")
                start = truth.now()
                assert start is not None and front_gap_mm(start) == pytest.approx(300.0, abs=1.0)
                judged(link, timeline, truth, algorithms)
            finally:
                truth.close()
                timeline.close()
    finally:
        if launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)
        launcher.communicate(timeout=60)


def at_rest(truth: TruthTrace) -> dict[str, Any]:
    """The pose once the motor's last batch of steps has reached the world (its motors off)."""
    return wait_until(
        lambda: (t := truth.now()) is not None and not t["moving"] and t, 60, "the robot at rest"
    )


def drive_at_the_wall(link: PcLink, timeline: TokenTimeline) -> tuple[list[Snapshot], list[Snapshot]]:
    """``s 600`` toward the wall 30 cm away: main's frames since, and those from the drive on."""
    t1 = time.monotonic()
    run_file(link, "s 600\n", 300.0)
    frames = timeline.since(t1)
    drive = first(frames, lambda s: s.direction == FORWARD, "the forward drive")
    return frames, frames[frames.index(drive) :]


def judge_clearance(link: PcLink, timeline: TokenTimeline, truth: TruthTrace, algorithms: str) -> None:
    """Ours: the drive stops short of the ALERT area and says why; the wall is not driven at again."""
    # 1. s 600 toward the wall 30 cm away: it drives most of the way and stops with the body
    #    outside the ALERT area — no front sonar ever reads under 4 cm, nothing is touched
    frames, after = drive_at_the_wall(link, timeline)
    closest = min(min(s.distances[i] for i in FRONT_PAIRS) for s in after)
    assert closest >= SEED_ALERT_BELOW_CM, [s.distances for s in after[-5:]]
    assert not [
        s for s in frames if s.abort_reason in (REASON["ALERT"], REASON["COLLISION"], REASON["STALL"])
    ]
    assert any(s.abort_reason == REASON["CLOSE"] for s in after), "the drive did not say the way was blocked"
    assert all(s.alert_lock == STOPPED for s in frames)
    stopped = at_rest(truth)
    gap = front_gap_mm(stopped)
    print(
        f"[ours] clearance: the front sonars read {closest} cm at the closest; the body stopped {gap:.0f} mm off"
    )
    assert SEED_ALERT_BELOW_CM * 10 < gap < 200.0, gap  # outside the ALERT area, most of the way
    assert stopped["collisions"] == 0

    # 2. the same drive again: whatever is left of the free way, the body stays outside the area
    t2 = time.monotonic()
    run_file(link, "s 600\n", 300.0)
    again = at_rest(truth)
    assert front_gap_mm(again) > SEED_ALERT_BELOW_CM * 10, front_gap_mm(again)
    assert all(min(s.distances[i] for i in FRONT_PAIRS) >= SEED_ALERT_BELOW_CM for s in timeline.since(t2))
    assert again["collisions"] == 0

    # 3. a drive back is taken whole
    run_file(link, "s -150\n", 300.0)
    back = at_rest(truth)
    assert again["x_mm"] - back["x_mm"] >= 140.0


def judge(link: PcLink, timeline: TokenTimeline, truth: TruthTrace, algorithms: str) -> None:
    """The three steps of the rule, as seen from main's frames and the world's truth."""
    # 1. s 600 toward the wall 30 cm away: ALERT aborts the drive near the wall, the lock allows
    #    only REVERSE (the action file then escapes and retries a few times, and gives up)
    frames, after = drive_at_the_wall(link, timeline)
    locked = first(after, lambda s: s.alert_lock == REVERSE, "the lock to REVERSE")
    during = after[: after.index(locked) + 1]
    under = [s for s in during if min(s.distances[i] for i in FRONT_PAIRS) < SEED_ALERT_BELOW_CM]
    assert under, f"no front sonar read under 4 cm before the lock: {[s.distances for s in during[-5:]]}"
    assert any(s.abort_reason == REASON["ALERT"] for s in after[after.index(locked) :]), "no ALERT abort"
    assert not [s for s in frames if s.abort_reason in (REASON["COLLISION"], REASON["STALL"])]
    stopped = truth.since(locked.t)[0]
    reading = min(under[-1].distances[i] for i in FRONT_PAIRS)
    print(
        f"[{algorithms}] ALERT: a front sonar read {reading} cm, the drive stopped with the body's "
        f"front {front_gap_mm(stopped):.0f} mm from the wall (collisions {stopped['collisions']})"
    )
    assert front_gap_mm(stopped) < 60.0  # it was the wall: the drive had come right up to it

    # 2. while locked, the other direction is refused: the motor's next move is the allowed one
    #    (the action file's own escape), and the robot never moved the refused way
    held = timeline.last()
    assert held is not None and held.alert_lock in OPPOSITE, held
    allowed = held.alert_lock
    # the pose once the motor's last batch of steps has reached the world (its motors off): the
    # truth between batches stands or runs on at the last batch's speed, so a sample taken as the
    # action file ended could lie behind where the aborted drive's last steps put the robot
    x2 = at_rest(truth)
    t2 = time.monotonic()
    run_file(link, drive_text(OPPOSITE[allowed], 100), 300.0)
    frames = timeline.since(t2)
    moved = first(frames, lambda s: s.move_seq != held.move_seq, "a new move")
    assert moved.direction == allowed, (moved, "the refused direction reached the motor")
    sign = 1.0 if OPPOSITE[allowed] == FORWARD else -1.0  # +X is forward
    before_move = [x2, *(t for at, t in list(truth.samples) if t2 <= at <= moved.t)]
    assert max(sign * (t["x_mm"] - x2["x_mm"]) for t in before_move) <= 1.0
    escape_taken(frames, held.move_seq, allowed, algorithms)

    # 3. the escape asked for: a drive in the allowed direction is taken and releases the lock
    held = timeline.last()
    assert held is not None
    if algorithms == "seed" and held.alert_lock == STOPPED:
        # the seed's robot got away during the retries of step 2 (a reading of 4 cm or more let
        # an escape run): nothing is locked any more, and no sonar reads ALERT
        assert min(held.distances) >= SEED_ALERT_BELOW_CM, held
        print(f"[{algorithms}] got away during the retries: nothing locked")
        return
    assert held.alert_lock in OPPOSITE, held
    escape = held.alert_lock
    x3 = truth.now()
    assert x3 is not None
    t3 = time.monotonic()
    run_file(link, drive_text(escape, 150), 300.0)
    escape_taken(timeline.since(t3), held.move_seq, escape, algorithms)
    end = truth.now()
    assert end is not None
    away = x3["x_mm"] - end["x_mm"] if escape == REVERSE else end["x_mm"] - x3["x_mm"]
    print(f"[{algorithms}] escape {'back' if escape == REVERSE else 'forward'}: moved {away:.0f} mm")


def escape_taken(frames: list[Snapshot], seq_before: int, escape: int, algorithms: str) -> bool:
    """The escape in ``frames``: the motor runs a new move in the allowed direction while main's
    lock reads STOPPED (released as it started). If the lock comes back during that move (only
    the seed's pilot stops an escape), it allows the escape's opposite and a sonar read ALERT.
    True if it came back."""
    taken = first(
        frames,
        lambda s: s.move_seq != seq_before and s.direction == escape and s.alert_lock == STOPPED,
        "the escape running with the lock released",
    )
    later = frames[frames.index(taken) :]
    relocked = [s for s in later if s.alert_lock != STOPPED and s.move_seq == taken.move_seq]
    if relocked and algorithms == "seed":
        # the seed's rule: the escape is stopped too while any sonar reads ALERT
        assert relocked[0].alert_lock == OPPOSITE[escape]
        seen = later[: later.index(relocked[0]) + 1]
        assert any(min(s.distances) < SEED_ALERT_BELOW_CM for s in seen)
    return bool(relocked)
