"""The period trigger on the ring: an action-file drive's synchronisations are 100 ms apart.

The whole ring with the world simulator (``tokenring up --actions``), copro hosting the Localizer
with its default configuration; the judge reads the data log itself and checks what
``tokenring analyze --json`` says against it, and that the log replays to the same bits.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from modules.localization.logs import read_log
from tests.support.processes import run_tokenring


@pytest.mark.slow
@pytest.mark.timeout(600)  # its hang guard: the ring boots, calibrates and drives on a loaded machine
def test_an_action_drive_synchronises_every_100_ms_of_sensor_time(procs, ring_name, endpoint, tmp_path):
    logs = tmp_path / "logs"
    config = tmp_path / "localization.yaml"
    config.write_text(yaml.safe_dump({"logs": {"directory": str(logs)}}))  # the default trigger
    actions = tmp_path / "drive.act"
    actions.write_text("e\ns 500\nr 90\ns 300\n")
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--world", "square", "--speed", "5",
        "--actions", str(actions), "--localizer", str(config), "--duration", "400",
    )  # fmt: skip
    output, _ = launcher.communicate(timeout=540)  # the ring stops itself after the action file
    assert launcher.returncode == 0, output[-3000:]
    (data_log,) = sorted(logs.glob("*.trlog"))

    log = read_log(data_log)
    assert log.header["config"]["sync"]["trigger"]["mode"] == "period"
    stamps = np.array([r[0] for r in log.records if r[1] == "S" and r[2] == "S"])
    assert len(stamps) > 150, output[-3000:]
    assert np.all(stamps % 100 == 0)  # every synchronisation at a grid time of the odometry
    periods = np.diff(stamps)
    assert np.all((periods > 0) & (periods % 100 == 0))
    # a period over 100 ms only where copro saw no step counter for over a second (a stall of the
    # loaded machine: the grid times in between are skipped, never made up)
    odometry = np.array([r[0] for r in log.records if r[1] == "O" and r[2] == "R"])
    for before, after in zip(stamps[:-1][periods > 100], stamps[1:][periods > 100], strict=True):
        inside = np.sort(odometry[(odometry >= before) & (odometry < after + 100)])
        assert np.diff(inside).max() > 1000, (before, after, inside)
    exact = float(np.mean(periods == 100))
    assert exact > 0.9

    summary = json.loads(run_tokenring("analyze", str(data_log), "--json").stdout)
    assert summary["sync"]["count"] == len(stamps)
    assert summary["sync"]["median_period_ms"] == 100.0
    assert summary["sync"]["within_98_102ms"] == pytest.approx(exact)
    assert summary["sync"]["within_95_105ms"] == pytest.approx(exact)
    checked = run_tokenring("replay", str(data_log), "--out", str(tmp_path / "again.trlog"), "--check")
    assert checked.returncode == 0, checked.stdout + checked.stderr
