"""A short seeded random chaos run on real node processes, judged again by the tests' own judge."""

from __future__ import annotations

import json
import subprocess

import pytest

from tests.support.processes import REPO, TOKENRING
from tests.support.ringjudge import judge_ledgers


@pytest.mark.slow
def test_a_random_schedule_runs_reproducibly_and_loses_nothing(tmp_path):
    ledger = tmp_path / "ledger"
    report_file = tmp_path / "report.json"
    args = ["chaos", "--random", "7", "--duration", "25", "--out", str(tmp_path), "--quiet"]
    result = subprocess.run(
        [*TOKENRING, *args, "--ledger", str(ledger), "--json", str(report_file), "--shrink-runs", "0"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(report_file.read_text())
    assert report["seed"] == 7 and report["operations"] > 5
    assert report["invariants"]["exactly_one_token_at_end"]
    assert report["commands"]["lost"] == 0 and report["commands"]["duplicated"] == 0
    # the schedule was written and the same seed writes the same schedule again, beside it
    again = subprocess.run(
        [*TOKENRING, *args, "--dry-run"], capture_output=True, text=True, timeout=60, cwd=REPO
    )
    assert again.returncode == 0, again.stderr
    first, second = tmp_path / "chaos-seed7.yaml", tmp_path / "chaos-seed7-2.yaml"
    assert second.read_text() == first.read_text()
    # the ledgers, judged by the tests' own checker (it shares no code with tokenring.chaos.checker)
    verdict = judge_ledgers(ledger)
    assert verdict.ok, str(verdict)
    assert verdict.acked > 100 and not verdict.lost and not verdict.duplicated
    assert verdict.acked == report["commands"]["acked"]
