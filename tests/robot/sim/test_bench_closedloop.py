"""bench.closedloop's Localizer settings: what ``--localizer`` lays over exploration mode reaches
the filter the robot drives with, and a misspelt key stops the run instead of being ignored."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.closedloop import write_json
from modules.copro import EXPLORATION_CONFIG
from modules.localization.config import ConfigError, layered
from modules.sim.closedloop import ClosedLoop, explore


def test_overrides_merge_into_nested_settings_and_leave_the_base_alone() -> None:
    base = {"walls": {"mode": "exploration", "association": {"min_wall_length_mm": 1000.0}}, "logs": {}}
    got = layered(base, {"walls": {"association": {"max_d_mm": 300.0}}, "filter": {"travel": {}}})
    assert got["walls"] == {
        "mode": "exploration",
        "association": {"min_wall_length_mm": 1000.0, "max_d_mm": 300.0},
    }
    assert got["filter"] == {"travel": {}}
    assert base["walls"]["association"] == {"min_wall_length_mm": 1000.0}  # not changed in place


def test_the_closed_loops_filter_runs_on_the_overridden_settings() -> None:
    config = layered(EXPLORATION_CONFIG, {"walls": {"shared_sigma_mm": 3.0}})
    loop = ClosedLoop("empty", seed=1, localizer_config=config)
    assert loop.core is not None
    assert loop.core.config["walls"]["shared_sigma_mm"] == 3.0
    assert loop.core.config["walls"]["mode"] == EXPLORATION_CONFIG["walls"]["mode"]  # kept


def test_a_misspelt_setting_stops_the_run() -> None:
    with pytest.raises(ConfigError, match="shared_sigma"):
        explore("empty", 1, overrides={"walls": {"shared_sigma": 3.0}}, minutes=0.01)


def test_the_json_holds_the_runs_so_far_without_their_logs(tmp_path: Path) -> None:
    path = tmp_path / "runs.json"
    write_json(str(path), [{"room": "empty", "seed": 1, "log": ["a move"], "rows": []}], ["--world", "empty"])
    document = json.loads(path.read_text())
    assert document["command"] == "python -m bench.closedloop --world empty"
    assert document["runs"] == [{"room": "empty", "seed": 1, "rows": []}]


def test_main_and_copro_see_the_token_as_often_as_asked() -> None:
    """``visit_ms`` stands for the ring's round: a slow ring's copro runs every 130 ms."""
    loop = ClosedLoop("empty", seed=1, visit_ms=130)
    seen: list[float] = []
    copro = loop._copro

    def visit() -> None:
        seen.append(loop.now)
        copro()

    loop._copro = visit  # type: ignore[method-assign]
    loop.run(minutes=0.02)  # 1.2 simulated seconds
    assert seen == [130.0 * k for k in range(10)]
