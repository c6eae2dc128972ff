"""config/syncaria.cfg, figure B.1 completed with every section of table B.1: it loads, gives the
Localizer the layer its values say, and ``tokenring up --localizer`` takes it where its LOPS
receivers stand (the Darmstadt hall) and refuses it elsewhere."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from modules.localization.config import ConfigError, load_config, sensor_set_layer
from modules.localization.seedconfig import read_seed_config
from tests.support.processes import REPO

SYNCARIA = REPO / "config" / "syncaria.cfg"
HALL_RECEIVERS = [[100.0, 100.0], [4900.0, 100.0], [100.0, 4900.0]]
SQUARE_LAPS = str(REPO / "actions" / "square-3-laps.act")
ROW = {
    "use": True,
    "synchronise": True,
    "position": True,
    "log_raw": True,
    "log_sync": True,
    "log_position": True,
}


def test_it_maps_to_the_layer_its_values_say() -> None:
    seed = read_seed_config(SYNCARIA)
    assert seed.localization_layer() == {
        "sensors": {
            "odometry": {**ROW, "filter": True},
            "gyro": {**ROW, "filter": True},
            "sonar": {**ROW, "filter": False},
            "lops": {**ROW, "filter": False},
            "compass": {"use": False},
            "correlator": {"use": False},
            "battery": {"use": False},
        },
        "sync": {
            "trigger": {"mode": "count", "sensor": "odometry", "count": 1, "min_period_ms": 0, "rounds": 0}
        },
        "filter": {"enabled": True, "initial_pose": "lops", "odometry_model": "arc"},
        "walls": {
            "mode": "darmstadt",
            "file": "darmstadt-hall",
            "history": 60,
            "max_distance_mm": 1400.0,
            "min_points_side": 15,
            "min_points_pairs": 10,
            "max_sigma_side_mm": 30.0,
            "max_sigma_d_pairs_mm": 35.0,
            "max_sigma_alpha_pairs_deg": 15.0,
            "association": {"max_d_mm": 400.0, "max_alpha_deg": 20.0},
        },
        "lops": {"receivers": HALL_RECEIVERS},
        "logs": {"data": "syncaria.trlog", "errors": "syncaria.trerr", "debug_level": 4, "error_log": True},
        "ui": "stdout",
        "actions": {"auto": True, "files": [SQUARE_LAPS] * 3},
    }
    assert (seed.ui, seed.mode, seed.debug_level) == ("stdout", "robot", 4)
    assert seed.actions.auto and seed.actions.files == (Path(SQUARE_LAPS),) * 3
    assert seed.offline is not None and seed.offline.input == Path("logs/syncaria.trlog")
    assert seed.offline.synchronised is False


def test_it_loads_by_path_and_by_name_and_says_what_does_not_apply() -> None:
    config = load_config(SYNCARIA)
    assert load_config("syncaria") == config
    assert config["sync"]["trigger"]["mode"] == "count" and config["filter"]["initial_pose"] == "lops"
    assert config["logs"]["debug"] is True and config["sensors"]["truth"]["use"]  # the reference stays
    assert config["walls"]["range_model"] == "tangent"  # config/localization.yaml's, the seed had none
    notes = [n.option for n in read_seed_config(SYNCARIA).notes()]
    assert notes[:4] == ["[Main] Anbindung", "[Gyroscop] Schnittstelle", "[Walls] max. Δd (oben / unten)",
                         "[Walls] max. Δα (oben / unten)"]  # fmt: skip
    assert notes[4:7] == ["[Lops] Robotername", "[Lops] Port", "[Lops] Schnittstelle"]
    assert len(notes) == 17  # and lopscpp's ten, the values the LOPS that up starts runs with


def up_plan(*argv: str):
    from modules.plugin import RobotExtension
    from tokenring.cli.commands import up
    from tokenring.contract.protocol import load_protocol

    parser = argparse.ArgumentParser()
    up.add_parser(parser.add_subparsers())
    args = parser.parse_args(["up", *argv])
    args.log_level = "info"  # the main parser's option, before the verb
    return RobotExtension().plan_up(args, load_protocol(REPO / "protocol.yaml"))


def test_up_takes_it_in_the_darmstadt_hall_and_refuses_it_where_its_lops_does_not_stand() -> None:
    planned = up_plan(
        "--sensors", "darmstadt", "--world", "darmstadt-hall", "--localizer", "config/syncaria.cfg"
    )
    assert planned.env["TOKENRING_LOCALIZER_CONFIG"] == str(SYNCARIA.resolve())
    config = load_config(SYNCARIA, under=sensor_set_layer("darmstadt", HALL_RECEIVERS))
    assert config["sensors"]["correlator"]["use"] is False  # the file lists its sensors: the set's lose
    with pytest.raises(
        ConfigError, match=r"syncaria.cfg:\d+: \[Lops\] X/Y-Position 2: 4900 100 mm, but the LOPS"
    ):
        up_plan("--sensors", "darmstadt", "--world", "office", "--localizer", "config/syncaria.cfg")
