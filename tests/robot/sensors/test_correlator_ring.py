"""The floor correlator on a real ring: main (a test program), motor and correlator (100) as OS
processes over Zenoh on loopback, the world simulator beside them. A straight drive commanded
through main's PC link shows up in correlator.data, read from the correlator's own frames at the
address protocol.yaml gives (a PyYAML/struct reader, nothing from tokenring): the sum moves by
the distance the world says the robot drove, within the model's noise once the readings in the
wrong direction are counted back, and the samples come more than 40 ms apart at the sensor."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from modules.description import keys as robot_keys
from modules.world import correlator as model
from tests.support.datawatch import DataChannelReader
from tests.support.hallway import ROOM, programs
from tests.support.processes import REPO
from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until
from tokenring.host.pclink import PcLink
from tokenring.transport.session import query_one

PROTOCOL = yaml.safe_load((REPO / "protocol.yaml").read_text())
NODES = PROTOCOL["nodes"]
CORRELATOR = NODES["correlator"]
STATES = PROTOCOL["enums"]["correlator_state"]


def wrapped(newer: int, older: int) -> int:
    """The difference of two values of an i32 that wraps (the reader's own arithmetic)."""
    return (newer - older + 2**31) % 2**32 - 2**31


@pytest.mark.slow
def test_a_straight_drive_moves_the_correlators_sum_by_the_distance(
    procs: Any, ring_name: str, endpoint: str, tmp_path: Path
) -> None:
    room = tmp_path / "hall.yaml"
    room.write_text(ROOM)
    directory = programs(tmp_path, ["motor", "correlator"])
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,correlator",
        "--programs", str(directory), "--world", str(room), "--speed", "10", "--seed", "4",
        "--bitrate", "max", "--duration", "90",
    )  # fmt: skip
    ids = [NODES[name]["id"] for name in ("main", "motor", "correlator")]
    with tap(endpoint) as session:
        reader = DataChannelReader(session, ring_name, "correlator")
        wait_ring(session, ring_name, ids, timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        link = PcLink(session, ring_name)

        def running() -> dict[str, int] | None:
            seen = [v for v in reader.values() if v["state"] == STATES["RUNNING"]]
            return seen[-1] if len(seen) >= 10 and seen[-1]["sample"] - seen[0]["sample"] >= 20 else None

        wait_until(running, 60, "correlator RUNNING for 20 samples", interval=0.05)
        wait_until(lambda: link.read("motor.data")["stamp_ms"] > 0, 10, "motor data", interval=0.05)

        # standing: the sum does not move, the newest increment is 0
        before = reader.newest()
        assert before is not None and before["increment_um"] == 0, before
        report_before = control(session, ring_name, CORRELATOR["id"], "program")["report"]
        t0 = query_one(session, robot_keys.world(ring_name, "state"))

        motor = link.read("motor.data")
        assert link.command("motor", "MOVE_FORWARD", distance_mm=500, speed_pct=100)["acknowledged"]

        def finished() -> dict | None:
            data = link.read("motor.data")
            return data if data["move_seq"] != motor["move_seq"] and data["state"] != 1 else None

        wait_until(finished, 60, "MOVE_FORWARD to finish", interval=0.02)
        t1 = query_one(session, robot_keys.world(ring_name, "state"))

        # every sample of the drive read: the sensor's stamps 300 ms past the world's end of it
        def past(value: dict[str, int] | None) -> bool:
            return value is not None and value["stamp_ms"] > t1["t_ms"] + 300

        after = wait_until(
            lambda: reader.newest() if past(reader.newest()) else None, 30, "samples past the move"
        )
        report_after = control(session, ring_name, CORRELATOR["id"], "program")["report"]
        seen = reader.values()
        reader.close()
    launcher.terminate()
    assert launcher.wait(60) == 0

    driven = math.hypot(t1["x_mm"] - t0["x_mm"], t1["y_mm"] - t0["y_mm"])
    assert driven > 450 and abs(t1["theta_rad"] - t0["theta_rad"]) < 1e-9, (t0, t1)
    moved_um = wrapped(after["forward_um"], before["forward_um"])
    samples = (after["sample"] - before["sample"]) % 65536
    # the robot stood before and after: backward readings (and the sum) moved only in between
    backward = report_after["backward"] - report_before["backward"]
    backward_um = report_after["backward_um"] - report_before["backward_um"]
    # backward readings are rare: the wrong directions (1 % steady, 15 % while accelerating) and
    # the world's own step-backs (a motor batch late by some ms at speed 10 leaves pose_at ahead
    # of the steps it then gets, and the pose steps back)
    assert backward <= max(3, 0.1 * samples), (backward, samples)
    assert backward_um <= 0.1 * driven * 1000, (backward_um, driven)
    # the increments sum to the distance within their noise (2 % a sample of at most 6 mm, 10 cm/s
    # over 60 ms; four standard deviations over the drive's samples; a µm's rounding a sample),
    # and within twice what read backwards: a sample read the wrong way round is off by twice
    # itself, and the world's step-backs the sum follows, as it follows the steps forward
    noise_mm = 4 * model.NOISE_REL * 6.0 * math.sqrt(samples) + samples / 1000.0
    error_mm = moved_um / 1000.0 - driven
    assert -noise_mm - 2 * backward_um / 1000.0 <= error_mm <= noise_mm, (error_mm, noise_mm, backward_um)

    running = [v for v in seen if v["state"] == STATES["RUNNING"]]
    assert running == seen[len(seen) - len(running) :]  # once running, it stays so
    for a, b in itertools.pairwise(running):
        assert b["stamp_ms"] > a["stamp_ms"] and (b["sample"] - a["sample"]) % 65536 > 0, (a, b)
    span = running[-1]["stamp_ms"] - running[0]["stamp_ms"]
    taken = (running[-1]["sample"] - running[0]["sample"]) % 65536
    # more than 40 ms a sample at the sensor (stamps are whole ms: one ms of slack at each end)
    assert (
        span + 2 >= model.SAMPLE_MIN_MS * taken
        and span <= (model.SAMPLE_MIN_MS + model.SAMPLE_JITTER_MS) * taken + 2
    )
    print(
        f"correlator: drove {driven:.1f} mm; the sum moved {moved_um / 1000:.1f} mm over {samples} samples, "
        f"{backward} backward ({backward_um / 1000:.1f} mm; noise bound {noise_mm:.1f} mm); "
        f"{span / taken:.1f} ms a sample"
    )
