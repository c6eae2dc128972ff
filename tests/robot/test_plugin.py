"""The robot's part of ``tokenring up`` (modules/plugin.py), planned from up's own parser: how much
faster emulated time runs, which services start, what the nodes are told."""

from __future__ import annotations

import argparse
import json

import pytest

from modules.plugin import RobotExtension
from tests.support.processes import REPO
from tokenring.contract.protocol import load_protocol


def plan(*argv: str):
    from tokenring.cli.commands import up

    parser = argparse.ArgumentParser()
    up.add_parser(parser.add_subparsers())
    args = parser.parse_args(["up", *argv])
    args.log_level = "info"  # the main parser's option, before the verb
    return RobotExtension().plan_up(args, load_protocol(REPO / "protocol.yaml"))


def motor_setting(
    monkeypatch: pytest.MonkeyPatch, sensors: str, name: str, environ: str | None
) -> str | None:
    """What ``up --sensors SENSORS`` tells the nodes in the setting ``name`` (an environment
    variable), with the caller's own ``environ`` value set beforehand (None: unset)."""
    if environ is None:
        monkeypatch.delenv(name, raising=False)
    else:
        monkeypatch.setenv(name, environ)
    return plan("--sensors", sensors).env.get(name)


@pytest.mark.parametrize("sensors", [[], ["--sensors", "hamburg"], ["--sensors", "darmstadt"]])
def test_the_world_s_speed_up_is_the_ring_s_whatever_the_sensors(sensors: list[str]) -> None:
    """--speed K runs the world K times faster, and the emulated wire with it: a round of the
    ring must stay as short in emulated time as on the real hardware."""
    planned = plan("--speed", "10", *sensors)
    assert planned.speedup == 10.0
    names = [s.name for s in planned.services]
    assert names == (["world", "lops"] if "darmstadt" in sensors else ["world"])
    assert planned.env.get("TOKENRING_SENSORS") == ("darmstadt" if "darmstadt" in sensors else None)
    if "darmstadt" in sensors:  # LOPS and copro's Localizer are told the same receivers
        lops = planned.services[1].argv
        given = lops[lops.index("--receivers") + 1 : lops.index("--receivers") + 4]
        told = json.loads(planned.env["TOKENRING_LOPS_RECEIVERS"])
        assert [[float(v) for v in g.split(",")] for g in given] == told and len(told) == 3
    else:
        assert "TOKENRING_LOPS_RECEIVERS" not in planned.env


def test_without_a_world_nothing_runs_faster_and_no_lops_starts() -> None:
    planned = plan("--speed", "10", "--no-world", "--sensors", "darmstadt")
    assert planned.speedup == 1.0 and planned.services == []
    assert planned.env["TOKENRING_SENSORS"] == "darmstadt"  # copro's Localizer is told all the same


def test_a_bundled_localizer_configuration_is_named_and_a_file_of_that_name_wins(
    tmp_path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--localizer early-ekf`` is the seed's early filter shipped in config/: copro is told
    its path; a file called early-ekf in the working directory is the user's and wins."""
    from modules.localization.config import load_config, sensor_set_layer
    from tokenring import UsageError

    monkeypatch.chdir(tmp_path)
    planned = plan("--sensors", "darmstadt", "--localizer", "early-ekf")
    told = planned.env["TOKENRING_LOCALIZER_CONFIG"]
    assert told == str(REPO / "config" / "early-ekf.yaml")
    early = load_config(told, under=sensor_set_layer("darmstadt"))
    fused = {name for name, sensor in early["sensors"].items() if sensor["use"] and sensor["filter"]}
    assert fused == {"odometry", "gyro"} and early["filter"]["estimate"] == ["glide"]
    (tmp_path / "early-ekf").write_text("filter: {enabled: false}\n")
    assert plan("--localizer", "early-ekf").env["TOKENRING_LOCALIZER_CONFIG"] == str(tmp_path / "early-ekf")
    with pytest.raises(UsageError, match="no-such-config"):
        plan("--localizer", "no-such-config")
