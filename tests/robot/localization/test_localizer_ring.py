"""End to end: the whole ring with the world simulator, copro hosting the Localizer, main driving an
action file — the fused pose on copro.data, the data log against the truth, and its replay."""

from __future__ import annotations

import math
import signal

import pytest
import yaml

from bench.localization import run_actions, wait_for_compass, world_now
from modules.description import keys as robot_keys
from modules.localization.logs import read_log
from modules.pc.analysis import analyse
from modules.pc.replay import replay
from tests.support.ringutil import tap, wait_main_answers, wait_until
from tokenring.host.pclink import open_link
from tokenring.transport.session import query


@pytest.mark.slow
def test_action_file_drive_with_the_localizer_on_copro(procs, ring_name, endpoint, tmp_path):
    logs = tmp_path / "logs"
    config = tmp_path / "localization.yaml"
    compass_sigma_deg = 1.5
    config.write_text(
        yaml.safe_dump(
            {"logs": {"directory": str(logs)}, "filter": {"compass": {"sigma_deg": compass_sigma_deg}}}
        )
    )
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--world", "square", "--speed", "10",
        "--bitrate", "max", "--duration", "400",
        env={"TOKENRING_LOCALIZER_CONFIG": str(config)},
    )  # fmt: skip
    try:
        with tap(endpoint) as session:
            link = open_link(session, ring_name, wait=60.0)

            wait_main_answers(link)
            link.command("compass", "CALIBRATE", timeout=10.0)
            wait_for_compass(link, 90.0)
            # the filter's pose is one made after the calibration turn ended, heading included
            calibrated_ms = world_now(session, ring_name)
            wait_until(
                lambda: (
                    (pose := link.read("copro.data"))["pose_stamp_ms"] > calibrated_ms
                    and pose["pose_valid"] == 7
                ),
                60,
                "a fused pose from after the calibration",
            )
            start_ms = world_now(session, ring_name)
            state = run_actions(link, "e\ns 1000\nr 90\ns 600\n", "test.act", 60, 120.0)
            assert not state["running"], state
            assert state["finished"]["why"] == "action file done", state
            copro = link.read("copro.data")
            assert copro["pose_source"] == 2 and copro["pose_valid"] == 7, copro
            (_, truth), *_ = query(session, robot_keys.world(ring_name, "state"), timeout=2.0)
            truth = truth["result"]
            assert math.hypot(copro["pose_x_mm"] - truth["x_mm"], copro["pose_y_mm"] - truth["y_mm"]) < 60.0
    finally:
        if launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)
    output, _ = launcher.communicate(timeout=60)
    (data_log,) = sorted(logs.glob("*.trlog"))
    log = read_log(data_log)
    assert not log.truncated, output[-2000:]
    summary, _ = analyse(data_log)
    k, o = summary["sources"]["K"], summary["sources"]["O"]
    assert k["end_error_mm"] < 50.0, summary
    assert k["end_error_mm"] < o["end_error_mm"], summary
    # The filter estimates the compass's offset too, so it knows the heading about as well as the
    # compass's stated accuracy lets it split the two: far better than dead reckoning, within 2σ.
    assert abs(k["end_heading_error_deg"]) < abs(o["end_heading_error_deg"]) / 4, summary
    assert abs(k["end_heading_error_deg"]) < 2 * compass_sigma_deg, summary
    moved = [
        r
        for r in log.records
        if r[1] == "O" and r[2] == "C" and r[0] > start_ms and (r[3]["dl"] or r[3]["dr"])
    ]
    assert len(moved) > 50
    # the logged online run replays to the same bits
    result = replay(data_log, tmp_path / "replayed.trlog")
    assert result.identical, result.first_difference
