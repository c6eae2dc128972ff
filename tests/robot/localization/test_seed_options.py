"""The seed's options the YAML lacked (table B.1): the debug level, the error log's own switch,
each sensor's synchronise and position switches, and the console's ui and actions."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from modules.localization.config import ConfigError, load_config, parse_config
from modules.localization.localizer import LocalizationCore, open_logs
from modules.localization.logs import ErrorLog, read_log
from tests.support.locsim import drive

DRIVE = [("s", 600.0)]  # long enough for walls fitted, a W position


def written(tmp_path: Path, **kwargs: Any) -> list[str]:
    """The classes an error log keeps of one message of each."""
    path = tmp_path / "e.trerr"
    with ErrorLog(path, "start", **kwargs) as log:
        for cls in "FEWID":
            log.message(cls, 0, cls)
    return [record[1] for record in read_log(path).records]


@pytest.mark.parametrize(
    ("level", "kept"),
    [(0, ["F"]), (1, ["F", "E"]), (2, ["F", "E", "W"]), (3, ["F", "E", "W", "I"]), (4, list("FEWID"))],
)
def test_the_debug_level_keeps_its_class_and_the_graver_ones(tmp_path: Path, level: int, kept) -> None:
    assert written(tmp_path, level=level) == kept


def test_without_a_level_debug_says_four_or_three(tmp_path: Path) -> None:
    assert written(tmp_path) == ["F", "E", "W", "I"]
    assert written(tmp_path, debug=True) == list("FEWID")
    with pytest.raises(ValueError, match="debug level 5"):
        ErrorLog(tmp_path / "x.trerr", "start", level=5)


def test_debug_level_and_the_older_debug_read_as_one() -> None:
    assert load_config(None)["logs"]["debug_level"] == 3
    assert load_config({"logs": {"debug": True}})["logs"]["debug_level"] == 4
    assert load_config({"logs": {"debug": False}})["logs"]["debug_level"] == 3
    assert load_config({"logs": {"debug_level": 4}})["logs"]["debug"] is True
    assert load_config({"logs": {"debug_level": 1}})["logs"]["debug"] is False
    assert load_config({"logs": {"debug": True, "debug_level": 4}})["logs"]["debug_level"] == 4


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("logs:\n  debug_level: 5\n", "x.yaml:2: logs.debug_level: must be 0-4 (0 fatal only"),
        ("logs:\n  debug: true\n  debug_level: 2\n", "x.yaml:2: logs.debug: True says debug level 4, but"),
        ("logs:\n  error_log: maybe\n", "x.yaml:2: logs.error_log: expected true or false"),
        ("ui: curses\n", "x.yaml:1: ui: must be one of stdout, ncurses, none, got 'curses'"),
        ("actions:\n  files: [a, b, c, d]\n", "x.yaml:2: actions.files: expected up to 3 file names"),
        ("actions:\n  files: [3]\n", "actions.files: expected up to 3 file names (or null), got [3]"),
        ("actions:\n  auto: true\n", "x.yaml:2: actions.auto: true drives the first of actions.files"),
        (
            "sensors:\n  compass: {synchronise: false, filter: true}\n",
            "x.yaml:2: sensors.compass.filter: needs the sensor's synchronised data, and synchronise is false",
        ),
        (
            "sensors:\n  compass:\n    synchronise: false\n    position: true\n",
            "x.yaml:4: sensors.compass.position: needs the sensor's synchronised data",
        ),
        (
            "sensors:\n  odometry: {synchronise: false}\n",
            "x.yaml:2: sensors.odometry.synchronise: the odometry's synchronised steps are the track",
        ),
        (
            "sensors:\n  compass: {position: false, log_position: true}\n",
            "sensors.compass.log_position: no position is computed",
        ),
    ],
)
def test_a_bad_new_option_names_its_line(text: str, message: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "x.yaml")
    assert message in str(caught.value)


def test_a_sensor_not_synchronised_has_nothing_synchronised_left_on() -> None:
    compass = load_config({"sensors": {"compass": {"synchronise": False}}})["sensors"]["compass"]
    assert compass["use"] and compass["log_raw"]
    assert not (compass["position"] or compass["log_sync"] or compass["log_position"] or compass["filter"])


def test_relative_action_files_are_the_yaml_files_folder(tmp_path: Path) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text(f"ui: ncurses\nactions:\n  auto: true\n  files: [laps.act, null, {tmp_path}/x.act]\n")
    config = load_config(path)
    assert config["ui"] == "ncurses"
    assert config["actions"] == {
        "auto": True,
        "files": [str(tmp_path / "laps.act"), None, str(tmp_path / "x.act")],
    }


def test_the_error_log_switch_leaves_the_data_log(tmp_path: Path) -> None:
    config = load_config({"logs": {"error_log": False}})
    data, errors = open_logs(config, tmp_path)
    assert errors is None and data is not None
    data.close()
    data, errors = open_logs(load_config({"logs": {"debug_level": 1}}), tmp_path / "b")
    assert data is not None and errors is not None and errors.level == 1
    data.close()
    errors.close()


def fed(config: dict[str, Any], tmp_path: Path) -> tuple[LocalizationCore, list[list[Any]]]:
    data, errors = open_logs(load_config(config), tmp_path)
    core = LocalizationCore(load_config(config), data_log=data, error_log=errors)
    for sample in drive(DRIVE, seed=2):
        core.feed(sample)
        core.maybe_sync()
    core.close()
    assert data is not None
    return core, read_log(data.path).records


def kinds(records: list[list[Any]], source: str) -> set[str]:
    return {kind for _, letter, kind, _ in records if letter == source}


def test_a_sensor_not_synchronised_is_logged_raw_and_nothing_more(tmp_path: Path) -> None:
    core, records = fed({"sensors": {"compass": {"synchronise": False}}}, tmp_path)
    assert kinds(records, "M") == {"R"}  # no synchronised record, no position
    assert "M" not in core.positions and "K" in core.positions
    assert core.ekf is not None and core.ekf.gates.as_dict()["accepted"].get("compass", 0) == 0
    every, records = fed({}, tmp_path / "all")
    assert kinds(records, "M") == {"R", "C", "P"} and "M" in every.positions


def test_a_sensor_without_its_position_stores_none(tmp_path: Path) -> None:
    every, _ = fed({}, tmp_path / "all")
    assert {"O", "W"} <= set(every.positions)
    core, records = fed(
        {"sensors": {"odometry": {"position": False}, "sonar": {"position": False}}}, tmp_path
    )
    assert "O" not in core.positions and "W" not in core.positions
    assert kinds(records, "O") == {"R", "C"}  # synchronised (the filter's steps), no position
    assert core.dead_reckoning is not None and core.positions["K"]["valid"] == [True, True, True]
