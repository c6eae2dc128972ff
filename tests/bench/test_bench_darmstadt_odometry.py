"""``python -m bench.darmstadt``'s odometry and synchronisation rows (issue 53): the drive-alone end
error of a path re-anchored on the truth, the rows beside the seed's figures, the ring benchmark's
file they come from; and the seed's drive itself in the Darmstadt hall (slow: about a minute)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bench import darmstadt
from modules.description import load_world


def test_the_drive_alone_is_judged_after_a_rigid_re_anchoring_on_the_truth() -> None:
    # the truth: a calibration turn at (1000, 1000), then 3 m along +Y (from t = 10 s to 40 s)
    truth = np.array(
        [[0, 1000, 1000, 0.0], [10_000, 1000, 1000, math.pi / 2], [40_000, 1000, 4000, math.pi / 2]]
    )
    # dead reckoning: lost 30° and 100 mm in the calibration turn, then 3 m with a 2° heading error
    off = math.radians(2.0)
    rows = [
        (0, {"x": 0.0, "y": 0.0, "psi": 0.0}),
        (10_000, {"x": 100.0, "y": 0.0, "psi": math.radians(60)}),
        (40_000, {"x": 100.0 + 3000 * math.cos(math.radians(60) + off), "y": 3000 * math.sin(math.radians(60) + off), "psi": math.radians(62)}),
    ]  # fmt: skip
    judged = darmstadt.drive_alone(rows, truth, 10_000)
    assert judged["end_error_mm"] == pytest.approx(2 * 3000 * math.sin(off / 2))
    assert judged["heading_error_deg"] == pytest.approx(2.0)
    # from the very start the calibration turn's loss counts too
    assert darmstadt.drive_alone(rows, truth, 0)["end_error_mm"] > 1000


def summary(**parts: object) -> dict:
    return {"seeds": [1, 2, 3], **parts}


def test_the_rows_stand_beside_the_seed_s_figures() -> None:
    odometry = {
        "world": "darmstadt-hall",
        "spread": {
            "end_error_mm": {"median": 1777.4, "min": 425.0, "max": 2748.0},
            "heading_error_deg": {"median": 36.0, "min": 23.0, "max": 64.0},
        },
    }
    sync = {
        "file": "syncregular-x.json",
        "speed": "5",
        "lines": [
            {"mode": "sip", "runs": 3, "within_98_102ms": 0.855, "within_98_102ms_range": [0.79, 0.93], "arrival_98_102ms": 0.03},
            {"mode": "ours", "runs": 3, "within_98_102ms": 0.024, "arrival_98_102ms": None},
        ],
    }  # fmt: skip
    section = darmstadt.section_md(
        summary(odometry_seed_drive=odometry, sync_regularity=sync), "darmstadt-x.json"
    )
    lines = section.splitlines()
    row = next(line for line in lines if "end error (mm)" in line)
    assert "`darmstadt-hall`" in row and "| 1777 (425–2748) | more than 1500 mm |" in row
    assert any("+36 (+23–+64)" in line for line in lines)
    sip = next(line for line in lines if "SIPs, every 100 ms" in line)
    assert "85.5 % (79.0 %–93.0 %) / 3.0 % (3.0 %–3.0 %)" in sip and "(results/syncregular-x.json)" in sip
    assert "95–105 ms, over 85 % within 98–102 ms" in sip
    tick = next(line for line in lines if "every loop tick" in line)
    assert "2.4 % (2.4 %–2.4 %) / –" in tick
    # a summary of the sensor models alone keeps its section as it was
    assert "end error" not in darmstadt.section_md(summary(), "darmstadt-y.json")


def test_the_synchronisation_comes_from_the_newest_ring_benchmark_file(tmp_path: Path) -> None:
    assert darmstadt.sync_regularity(tmp_path) is None
    line = {"mode": "sip", "trigger": "seedcount", "source": "online", "runs": 3, "within_98_102ms": 0.9}
    other = {**line, "trigger": "period"}
    (tmp_path / "syncregular-2026-01-01.json").write_text(json.dumps({"speed": "5", "table": [line]}))
    (tmp_path / "syncregular-2026-02-01.json").write_text(
        json.dumps({"speed": "2", "table": [other, {**line, "within_98_102ms": 0.95}]})
    )
    found = darmstadt.sync_regularity(tmp_path)
    assert found is not None and found["file"] == "syncregular-2026-02-01.json" and found["speed"] == "2"
    assert [(x["mode"], x["within_98_102ms"]) for x in found["lines"]] == [("sip", 0.95)]


def test_the_hall_is_the_square_with_a_slippery_floor_for_turns() -> None:
    hall, square = load_world("darmstadt-hall"), load_world("square")
    assert [w.as_tuple() for w in hall.walls] == [w.as_tuple() for w in square.walls]
    assert (hall.start, hall.circles) == (square.start, square.circles)
    assert hall.floor.glide_factor > square.floor.glide_factor
    assert (hall.floor.glide_spread, hall.floor.step_scale, hall.floor.step_noise) == (
        square.floor.glide_spread,
        square.floor.step_scale,
        square.floor.step_noise,
    )


@pytest.mark.slow
@pytest.mark.timeout(600)  # about 15 simulated minutes: 70 s on an idle core, twice that on a busy one
def test_the_seed_s_drive_in_the_hall_loses_the_odometry_by_metres() -> None:
    """World seed 2: three laps by the action navigator; dead reckoning ends beyond the seed's 1.5 m."""
    drive = darmstadt.odometry_seed_drive(2)
    assert drive["finished"] == "action file done"
    assert drive["end_error_mm"] > 1500 and drive["heading_error_deg"] > 10
