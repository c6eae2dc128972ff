"""The localisation's YAML configuration: the shipped defaults, and a clear message for every error."""

from __future__ import annotations

from pathlib import Path

import pytest

from modules.localization.config import (
    DEFAULTS,
    REPOSITORY_SETTINGS,
    ConfigError,
    default_config_path,
    load_config,
    parse_config,
)
from tests.support.processes import run_tokenring


def test_shipped_file_spells_out_exactly_the_defaults() -> None:
    assert default_config_path().exists()
    # the built-in defaults, and where the file turns on issue 21's sonar model and noise
    assert load_config(default_config_path()) == load_config(REPOSITORY_SETTINGS)
    for section, keys in REPOSITORY_SETTINGS.items():
        for key in keys:
            assert DEFAULTS[section][key] != load_config(default_config_path())[section][key]
    assert load_config(None) == DEFAULTS
    assert parse_config("", "empty.yaml") == DEFAULTS


def test_partial_file_overrides_only_what_it_names() -> None:
    config = parse_config("filter:\n  odometry_model: straight\nsync:\n  trigger: {rounds: 4}\n", "x.yaml")
    assert config["filter"]["odometry_model"] == "straight"
    assert config["sync"]["trigger"] == {
        "mode": "period",
        "sensor": "odometry",
        "period_ms": 100,
        "count": 1,
        "min_period_ms": 100,
        "rounds": 4,
    }
    assert config["walls"] == DEFAULTS["walls"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("sensors:\n  lidar: {use: true}\n", "x.yaml:2: sensors.lidar: unknown key (known here: odometry"),
        (
            "sensors:\n  compass: {use: maybe}\n",
            "x.yaml:2: sensors.compass.use: expected true or false, got 'maybe'",
        ),
        ("sensors:\n  truth: {filter: true}\n", "sensors.truth.filter: the ground truth is a reference only"),
        (
            "sync:\n  trigger:\n    sensor: sextant\n",
            "x.yaml:3: sync.trigger.sensor: must be one of odometry",
        ),
        ("sync:\n  trigger:\n    count: 0\n", "x.yaml:3: sync.trigger.count: must be at least 1"),
        ("sync:\n  trigger: {count: 1.5}\n", "sync.trigger.count: expected a whole number, got 1.5"),
        ("sensors:\n  odometry: {use: false}\n", "sync.trigger.sensor: odometry is not used"),
        (
            "filter:\n  odometry_model: spline\n",
            "x.yaml:2: filter.odometry_model: must be one of arc, straight",
        ),
        ("filter:\n  estimate: [glide, wheelbase]\n", "filter.estimate: unknown state 'wheelbase'"),
        (
            "filter:\n  estimate: [glide, step_scale_mean]\n",
            "filter.estimate: step_scale_mean needs step_scale",
        ),
        (
            "filter:\n  initial_pose: {x_mm: 1}\n",
            "filter.initial_pose: expected world, motor or {x_mm, y_mm, heading_deg}",
        ),
        ("filter:\n  initial_pose: somewhere\n", "filter.initial_pose: expected world, motor"),
        ("filter:\n  compass: {mode: median}\n", "filter.compass.mode: must be one of newest, mean"),
        ("filter:\n  gate_probability: 1.5\n", "filter.gate_probability: must be in [0.5, 1), got 1.5"),
        ("filter:\n  noise: {distance_rel: -1}\n", "filter.noise.distance_rel: must not be negative"),
        ("filter:\n  noise: {distance_rel: .nan}\n", "filter.noise.distance_rel: expected a number"),
        ("filter: 3\n", "x.yaml:1: filter: expected a mapping"),
        ("walls:\n  mode: slam\n", "walls.mode: must be one of darmstadt, exploration, off"),
        ("walls:\n  pairs: [[3, 9]]\n", "walls.pairs: expected pairs of sonar indices 0..7, got [3, 9]"),
        ("walls:\n  side_sensors: [12]\n", "walls.side_sensors: sonar index 12 is not in 0..7"),
        ("walls:\n  min_points_side: 2\n", "walls.min_points_side: needs at least 3 points"),
        ("robot:\n  mm_per_step: 0\n", "robot.mm_per_step: must be positive"),
        ("filter:\n  gyro: {sigma_deg: 0}\n", "filter.gyro.sigma_deg: must be positive"),
        ("filter:\n  correlator: {sigma_rel: 0}\n", "filter.correlator.sigma_rel: must be positive"),
        ("robot:\n  sonars: [[1, 2]]\n", "robot.sonars: entry 0: expected [x_mm, y_mm, angle_deg]"),
        ("robot:\n  sonars: lidar\n", "robot.sonars: expected robot"),
        ("logs:\n  data: 'run-{when}.trlog'\n", "logs.data: only {start} may be substituted"),
        ("logs: {enabled: yes please}\n", "logs.enabled: expected true or false"),
        ("filter:\n  - a\n", "x.yaml:1: filter: expected a mapping"),
        ("sync: {trigger: [1\n", "x.yaml:2: not valid YAML"),
    ],
)
def test_every_error_names_file_line_and_key(text: str, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_config(text, "x.yaml")
    assert message in str(info.value)
    assert info.value.exit_code == 2


def test_missing_file_and_command_line_exit_code(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ConfigError, match="no such configuration file"):
        load_config(tmp_path / "nope.yaml")
    from tokenring.cli.main import main

    bad = tmp_path / "bad.yaml"
    bad.write_text("filter:\n  odometry_model: spline\n")
    assert (
        main(["replay", str(tmp_path / "x.trlog"), "--out", str(tmp_path / "y.trlog"), "--config", str(bad)])
        == 2
    )
    err = capsys.readouterr().err
    assert "no such log file" in err or "bad.yaml:2: filter.odometry_model" in err


def test_up_refuses_a_bad_localizer_file_before_starting_anything(tmp_path: Path) -> None:
    bad = tmp_path / "loc.yaml"
    bad.write_text("filter:\n  enabled: maybe\n")
    result = run_tokenring("up", "--localizer", str(bad), "--duration", "1")
    assert result.returncode == 2
    assert f"{bad}:2: filter.enabled" in result.stderr
    assert "Traceback" not in result.stderr
    assert "starting" not in result.stdout  # refused before the launcher started a node


def test_a_sensor_set_lies_beneath_the_configuration_whose_keys_win(tmp_path) -> None:
    """``up --sensors darmstadt`` turns LOPS on in copro's Localizer; a file given beside it
    overrides only the keys it names."""
    from modules.localization.config import SENSOR_SET_CONFIG

    darmstadt = SENSOR_SET_CONFIG["darmstadt"]
    assert load_config()["sensors"]["lops"]["use"] is False  # off without the set
    assert load_config(None, under=darmstadt)["sensors"]["lops"]["use"] is True
    names_other_keys = tmp_path / "a.yaml"
    names_other_keys.write_text("sensors:\n  lops:\n    log_raw: false\nsync:\n  enabled: true\n")
    config = load_config(names_other_keys, under=darmstadt)
    assert config["sensors"]["lops"]["use"] is True and config["sensors"]["lops"]["log_raw"] is False
    turns_it_off = tmp_path / "b.yaml"
    turns_it_off.write_text("sensors:\n  lops: {use: false}\n")
    assert load_config(turns_it_off, under=darmstadt)["sensors"]["lops"]["use"] is False
    from modules.copro import EXPLORATION_CONFIG  # copro's own settings, a dict, take it the same way

    config = load_config(EXPLORATION_CONFIG, under=darmstadt)
    assert config["sensors"]["lops"]["use"] is True and config["logs"]["enabled"] is False
    broken = tmp_path / "c.yaml"
    broken.write_text("sensors:\n  lops: {use: maybe}\n")
    with pytest.raises(ConfigError, match=r"c.yaml:2: sensors.lops.use"):
        load_config(broken, under=darmstadt)
