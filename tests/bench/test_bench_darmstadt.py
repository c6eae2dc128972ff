"""``python -m bench.darmstadt``: the Darmstadt sensors' figures per seed with their spread, a
summary file that is never overwritten unasked, and RESULTS.md's section from the newest one."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from bench.report import darmstadt_md
from tests.support.processes import REPO


def run(*args: str) -> subprocess.CompletedProcess[str]:
    """The sensor models' parts (the odometry drive takes a minute per seed: its own tests)."""
    return subprocess.run(
        [sys.executable, "-m", "bench.darmstadt", "--parts", "gyro,lops,cycle", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=300,
    )


def test_one_seed_writes_its_figures_and_the_section_and_refuses_to_overwrite(tmp_path: Path) -> None:
    target = tmp_path / "darmstadt-x.json"
    done = run("--seeds", "7", "--json", str(target))
    assert done.returncode == 0, done.stderr
    result = json.loads(target.read_text())
    drive = result["lops_seed_drive"]["runs"][0]
    assert drive["seed"] == 7 and drive["measurements"] > 1500  # 98 ms triggers over the 3 laps
    assert 0 < drive["without_position"] < drive["measurements"]
    # a spread over one seed is that seed's value
    assert result["lops_seed_drive"]["spread"]["without_share"]["median"] == drive["without_share"]
    gyro = result["gyro_at_rest"]["runs"][0]
    assert gyro["samples"] == int(200_000 / 20.48) and 0 < gyro["commonest_share"] <= 1
    assert "## The Darmstadt sensors beside the seed" in done.stdout and "404 of 2024" in done.stdout

    again = run("--seeds", "7", "--json", str(target))
    assert again.returncode == 2 and "--force" in again.stderr and again.stderr.count("\n") == 1
    assert json.loads(target.read_text()) == result  # kept as it was

    bad = run("--seeds", "1,x")
    assert bad.returncode == 2 and "--seeds" in bad.stderr and "Traceback" not in bad.stderr


def test_the_report_takes_the_newest_summary(tmp_path: Path) -> None:
    assert darmstadt_md(tmp_path) == ""  # none yet: no section
    run("--seeds", "1", "--json", str(tmp_path / "darmstadt-old.json"))
    newer = json.loads((tmp_path / "darmstadt-old.json").read_text())
    newer["date"] = "2999-01-01T00:00:00"
    (tmp_path / "darmstadt-new.json").write_text(json.dumps(newer))
    section = darmstadt_md(tmp_path)
    assert "darmstadt-new.json" in section and "darmstadt-old.json" not in section
