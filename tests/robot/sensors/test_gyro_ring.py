"""The gyro on the whole ring: ``tokenring up --sensors darmstadt`` adds node gyro (90) to the
Hamburg eight. Read from the frames the gyro sends on (gyro.data at its address in
protocol.yaml, a PyYAML/struct reader, nothing from tokenring), it calibrates at rest and then
publishes rates with advancing sample counters and sensor stamps; LOPS, a service beside the
ring, puts its packets on its own key. Without ``--sensors`` the ring is the eight."""

from __future__ import annotations

import argparse
import itertools
import signal
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.support.datawatch import DataChannelReader
from tests.support.processes import REPO
from tests.support.ringutil import control, tap, wait_until

PROTOCOL = yaml.safe_load((REPO / "protocol.yaml").read_text())
GYRO = PROTOCOL["nodes"]["gyro"]
COPRO_ID = PROTOCOL["nodes"]["copro"]["id"]
STATES = PROTOCOL["enums"]["gyro_state"]
HAMBURG = ["main", "motor", "sonar", "compass", "copro", "map", "lcd", "charger"]


def test_the_default_ring_is_the_hamburg_eight_and_darmstadt_adds_the_gyro_and_correlator() -> None:
    """``up``'s node selection with the robot's extension loaded (``up``'s own parser)."""
    from tokenring.cli.commands import up
    from tokenring.contract.protocol import load_protocol
    from tokenring.host.launcher import plans_from_protocol

    protocol = load_protocol(REPO / "protocol.yaml")
    parser = argparse.ArgumentParser()
    up.add_parser(parser.add_subparsers())

    def ring(*argv: str) -> list[str]:
        args = parser.parse_args(["up", *argv])
        selection = up.node_selection(args, protocol)
        return [plan.name for plan in plans_from_protocol(protocol, selection, None)]

    assert ring() == HAMBURG
    assert ring("--sensors", "hamburg") == HAMBURG
    assert ring("--sensors", "darmstadt") == [*HAMBURG, "gyro", "correlator"]
    assert ring("--nodes", "main,gyro,correlator", "--sensors", "darmstadt") == ["main", "gyro", "correlator"]
    # the seed's body has no working floor correlator (seed 000 §3.3): the set leaves it out
    assert ring("--sensors", "darmstadt", "--algorithms", "seed") == [*HAMBURG, "gyro"]
    assert ring("--sensors", "darmstadt", "--algorithms", "ours,body=seed") == [*HAMBURG, "gyro"]
    assert ring("--sensors", "darmstadt", "--algorithms", "seed,body=ours")[-1] == "correlator"
    assert ring("--nodes", "main,gyro", "--sensors", "darmstadt", "--algorithms", "seed") == ["main", "gyro"]
    from tokenring import UsageError

    with pytest.raises(UsageError, match="gyro"):
        ring("--sensors", "darmstadt", "--nodes", "main,motor")
    with pytest.raises(UsageError, match="correlator"):
        ring("--sensors", "darmstadt", "--nodes", "main,gyro")


@pytest.mark.slow
def test_up_with_the_darmstadt_sensors_runs_a_calibrated_gyro_and_lops(
    procs: Any, ring_name: str, endpoint: str, tmp_path: Path
) -> None:
    logs = tmp_path / "logs"
    # the logs' folder and LOPS in the filter; --sensors darmstadt turns LOPS on and tells copro
    # where its receivers stand. The Darmstadt hall: the configuration's walls and start are its
    config = tmp_path / "localization.yaml"
    config.write_text(
        yaml.safe_dump({"logs": {"directory": str(logs)}, "sensors": {"lops": {"filter": True}}})
    )
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--world", "square", "--speed", "10",
        "--bitrate", "10M", "--sensors", "darmstadt", "--localizer", str(config), "--duration", "120",
    )  # fmt: skip
    try:
        with tap(endpoint) as session:
            reader = DataChannelReader(session, ring_name, "gyro")
            lops_packets: list[bytes] = []  # LOPS beside the ring: tables 6.1/6.2, never in the token
            lops = session.declare_subscriber(
                f"tokenring/{ring_name}/robot/lops/packets",
                lambda s: lops_packets.append(s.payload.to_bytes()),
            )

            def running_a_while() -> bool:
                seen = reader.values()
                running = [v for v in seen if v["state"] == STATES["RUNNING"]]
                return len(running) >= 20 and running[-1]["sample"] - running[0]["sample"] >= 100

            wait_until(running_a_while, 90, "gyro RUNNING for 100 samples", interval=0.2)
            seen = reader.values()
            reader.close()
            wait_until(lambda: sum(p[:2] == b"SD" for p in list(lops_packets)) >= 10, 30, "LOPS data packets")
            lops.undeclare()
            report = control(session, ring_name, GYRO["id"], "program")["report"]
            wait_until(
                lambda: (
                    (control(session, ring_name, COPRO_ID, "program")["report"].get("gates") or {})
                    .get("accepted", {})
                    .get("lops", 0)
                    >= 20
                ),
                60,
                "copro's filter to take LOPS's distances",
            )
    finally:
        if launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)
    output, _ = launcher.communicate(timeout=60)
    assert "Traceback" not in output, output[-3000:]
    assert "service lops" not in output, output[-3000:]  # it never died
    assert all(len(p) == 47 for p in lops_packets if p[:2] == b"SD"), lops_packets[:3]

    assert seen, "no frame from the gyro"  # it passed the token on
    states = [v["state"] for v in seen]
    # it calibrated first (the robot stands: no --explore), then ran: the states only go forward
    # (UNCALIBRATED before the program, CALIBRATING for 2 simulated s, which the tap may miss)
    assert states == sorted(states) and set(states) <= {0, 1, 2}, states
    calibration = report["calibration"]
    assert calibration["samples"] == 100 and report["calibration_restarts"] == 0, report
    assert calibration["spread"] < 1.0, report  # at rest: noise of a fraction of a count
    running = [v for v in seen if v["state"] == STATES["RUNNING"]]
    zero = {v["zero_mcounts"] for v in running}
    assert len(zero) == 1, zero  # one calibration, kept
    (zero_mcounts,) = zero
    # the world's zero point: mid-scale ± 20 counts (plus the warm-up's fraction of a count)
    assert abs(zero_mcounts / 1000 - 2048) < 21, zero_mcounts
    # at rest: raw values within a bit or two of the zero point, rates within their few bits
    # (one bit = 851 µrad/s), the sum of rates small
    assert all(abs(v["raw"] - zero_mcounts / 1000) < 2.5 for v in running), running[-5:]
    assert all(abs(v["rate_urad_s"]) < 2.5 * 851.4 for v in running), running[-5:]
    assert abs(running[-1]["angle_mrad"]) < 20, running[-1]
    # samples and their sensor stamps advance, 20.48 ms a sample
    for a, b in itertools.pairwise(running):
        assert b["stamp_ms"] > a["stamp_ms"] and (b["sample"] - a["sample"]) % 65536 > 0, (a, b)
    span = running[-1]["stamp_ms"] - running[0]["stamp_ms"]
    taken = (running[-1]["sample"] - running[0]["sample"]) % 65536
    assert abs(span - 20.48 * taken) <= 21, (span, taken)

    # copro's log: LOPS's packets as L records, stamped on arrival, counters in order; the
    # standing robot's position where the hall starts it (lopscpp's messages: the unit test)
    from modules.localization.logs import read_log

    (data_log,) = sorted(logs.glob("*.trlog"))
    records = read_log(data_log).records
    counters = [r[3]["v"]["counter"] for r in records if r[1] == "L" and r[2] == "R"]
    assert len(counters) >= 10 and counters == sorted(counters), counters
    start = yaml.safe_load((REPO / "modules/description/rooms/square.yaml").read_text())["start"]
    positions = [r[3] for r in records if r[1] == "L" and r[2] == "P"]
    assert positions and all(
        abs(p["x"] - start["x"]) < 60 and abs(p["y"] - start["y"]) < 60 for p in positions
    )
