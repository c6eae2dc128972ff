"""bench/spurious.py and its part of the report: configurations, the table, the aim, and which
earlier run the report takes a section from."""

from __future__ import annotations

import json
import os

import pytest

from bench.report import previous_section, spurious_aim, spurious_md, zero_bound_per_hour
from bench.spurious import GapWatch, pick_configs
from tokenring.errors import UsageError


def run(key: str, regenerated: int = 0, spurious: int = 0, seconds: float = 300.0) -> dict:
    return {
        "key": key,
        "label": f"label of {key}",
        "hog": "stress-ng --cpu 2" if key.endswith("+hog") else None,
        "seconds": seconds,
        "rounds": 14000,
        "regenerated": regenerated,
        "by_cause": {"fault": 0, "membership": 0, "spurious": spurious},
        "per_hour": regenerated * 3600 / seconds,
        "round_ms": {"median": 21.0, "p99_max": 90.0},
        "recon_ms": {"median": 840.0},
        "gaps_at_highest": {"p999_ms": 300.0, "max_ms": 500.0, "over_recon": 0},
        "load1": {"median": 3.0, "max": 5.0},
    }


def test_configurations_are_picked_by_key_and_an_unknown_one_is_refused():
    assert [c.key for c in pick_configs("idle")] == ["idle"]
    assert [c.key for c in pick_configs("speed10+hog,idle")] == ["idle", "speed10+hog"]
    assert len(pick_configs(None)) == 6
    assert all(c.hog == c.key.endswith("+hog") for c in pick_configs(None))
    with pytest.raises(UsageError, match="nope"):
        pick_configs("idle,nope")


def test_the_table_has_a_row_per_configuration_and_a_failed_one_says_why():
    section = {
        "minutes": 5,
        "runs": [run("idle"), run("speed10+hog", 12, 12), {"key": "x", "label": "X", "error": "boom"}],
    }
    text = spurious_md(section)
    assert "## Spurious regenerations" in text
    assert "| label of idle | 5.0 | 14000 |" in text
    assert "(< 36)" in text  # none seen in 5 minutes: below 36 per hour at 95 %
    assert "| 12 | 12 | 144.0 |" in text
    assert "failed: boom" in text


def test_the_aim_is_judged_on_the_default_pace_without_a_hog_only():
    quiet = {"runs": [run("idle"), run("robot"), run("speed10", 30, 30), run("idle+hog", 2, 2)]}
    ((aim, target, measured, verdict),) = spurious_aim(quiet)
    assert "default pace" in aim and target == "none" and verdict == "**met**"
    assert f"below {zero_bound_per_hour(600.0):.0f}/h" in measured
    missed = {"runs": [run("idle", 1, 1), run("robot")]}
    assert spurious_aim(missed)[0][3] == "**missed**"
    assert spurious_aim(None) == [] and spurious_aim({"runs": [run("speed10")]}) == []


def test_the_report_takes_the_latest_run_by_its_date_not_by_the_files_time(tmp_path):
    older, newer = tmp_path / "b.json", tmp_path / "a.json"
    older.write_text(json.dumps({"date": "2026-11-20T10:00:00", "sections": {"load": {"v": "old"}}}))
    newer.write_text(json.dumps({"date": "2026-11-21T10:00:00", "sections": {"load": {"v": "new"}}}))
    os.utime(newer, (1000, 1000))  # a checkout may leave the newer run with the older file time
    os.utime(older, (2000, 2000))
    section, source = previous_section("load", tmp_path, None)
    assert section == {"v": "new"} and source == "2026-11-21T10:00:00 (a.json)"
    assert previous_section("load", tmp_path, newer)[0] == {"v": "old"}  # never the current run's own file
    assert previous_section("spurious", tmp_path, None) is None


def test_the_gap_watch_takes_only_the_visits_since_its_last_poll():
    gaps = GapWatch()
    gaps.gaps = [0.02, 0.02, 0.5, 0.9]
    summary = gaps.summary(recon_s=0.84)
    assert summary["samples"] == 4 and summary["over_recon"] == 1 and summary["over_half_recon"] == 2
    assert summary["max_ms"] == 900.0 and summary["top_ms"][0] == 900.0
