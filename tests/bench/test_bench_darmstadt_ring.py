"""bench.darmstadt_ring's summary as RESULTS.md shows it, and its refusals (the runs themselves
launch rings for minutes: `python -m bench.darmstadt_ring`)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from bench.darmstadt_ring import section_md
from bench.report import darmstadt_ring_md
from tests.support.processes import REPO


def summary(date: str, early_mm: float) -> dict:
    def spread(v: float) -> dict[str, float]:
        return {"median": v, "min": v - 1.0, "max": v + 1.0}

    return {
        "date": date,
        "world": "darmstadt-hall",
        "speed": "10",
        "seeds": [1, 2, 3],
        "load_before": 1.5,
        "failed": 0,
        "spread": {
            "odometry_end_mm": spread(1777.0),
            "early_end_mm": spread(early_mm),
            "ours_end_mm": spread(1.2),
            "early_within_3sigma": spread(0.5),
            "ours_within_3sigma": spread(0.99),
        },
    }


def test_the_section_puts_each_figure_beside_the_seeds(tmp_path: Path) -> None:
    text = section_md(summary("2026-12-07T01:00:00", 351.0), "darmstadt_ring-x.json")
    rows = {line.split(" | ")[0].lstrip("| "): line for line in text.splitlines() if line.startswith("| ")}
    assert "1777 (1776–1778)" in rows["dead reckoning after the 3 laps, end error (mm)"]
    assert "> 1500 mm" in rows["dead reckoning after the 3 laps, end error (mm)"]
    assert "351 (350–352)" in rows["early filter (`--localizer early-ekf`), end error (mm)"]
    assert "1.2 (0.2–2.2)" in rows["ours, all sensors with LOPS fused, end error (mm)"]
    assert "world seed (1, 2, 3)" in text and "darmstadt_ring-x.json" in text


def test_the_report_takes_the_newest_summary(tmp_path: Path) -> None:
    (tmp_path / "darmstadt_ring-a.json").write_text(json.dumps(summary("2026-12-06T00:00:00", 999.0)))
    (tmp_path / "darmstadt_ring-b.json").write_text(json.dumps(summary("2026-12-07T00:00:00", 351.0)))
    (tmp_path / "darmstadt_ring-c.json").write_text("{not json")
    text = darmstadt_ring_md(tmp_path)
    assert "darmstadt_ring-b.json" in text and "351 (350–352)" in text and "999" not in text
    assert darmstadt_ring_md(tmp_path / "none") == ""


def test_bad_seeds_are_one_line_and_exit_2(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "bench.darmstadt_ring", "--seeds", "one", "--json", str(tmp_path / "x.json")],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "--seeds" in done.stderr
    assert not (tmp_path / "x.json").exists()
