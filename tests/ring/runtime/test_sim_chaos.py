"""Chaos in virtual time (``tokenring sim --chaos | --random | --replay``): a scenario file judged
as ``tokenring chaos`` judges real processes, the same run twice, a campaign of seeds, and a
failure's file run exactly again.

The commands are judged a second time by the test's own judge (tests/support/ringjudge.py, which
imports nothing of tokenring) from the probes' ledgers.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.support.processes import REPO, TOKENRING
from tests.support.ringjudge import judge_ledgers

#: every kind of fault a scenario can name, on a ring of five with respawn on and the probe
SCENARIO = """
ring: {nodes: [main, motor, sonar, compass, copro], respawn: true, workload: probe}
settle: 2.0
faults:
  - {at: 0.5, node: main, kind: crash}
  - {at: 2.0, node: sonar, kind: hang}
  - {at: 2.8, node: sonar, kind: resume}
  - {at: 3.5, node: all, kind: partition, value: "main,motor|sonar,compass,copro"}
  - {at: 4.5, node: all, kind: heal}
  - {at: 5.5, node: motor, kind: drop, value: 0.3}
  - {at: 5.5, node: compass, kind: duplicate}
  - {at: 6.5, node: all, kind: clear}
  - {at: 7.0, node: copro, kind: lose, count: 2}
  - {at: 8.0, node: compass, kind: leave}
  - {at: 8.6, node: compass, kind: join}
  - {at: 9.0, node: motor, kind: hang, soft: true}
  - {at: 9.6, node: motor, kind: resume}
"""


def sim(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*TOKENRING, "sim", *args], capture_output=True, text=True, timeout=600, cwd=cwd or REPO
    )


def run_scenario(
    tmp_path: Path, name: str, *extra: str
) -> tuple[subprocess.CompletedProcess[str], dict[str, Any]]:
    report = tmp_path / f"{name}.json"
    done = sim(*extra, "--json", str(report), "--quiet")
    assert done.returncode in (0, 1), done.stderr
    return done, json.loads(report.read_text())


def test_a_scenario_in_virtual_time_is_judged_as_on_real_processes_and_repeats_exactly(tmp_path: Path):
    scenario = tmp_path / "every-kind.yaml"
    scenario.write_text(SCENARIO)
    ledgers = tmp_path / "ledgers"
    done, report = run_scenario(
        tmp_path, "first", "--chaos", str(scenario), "--seed", "4", "--ledger", str(ledgers)
    )
    assert done.returncode == 0, done.stdout
    assert all(report["invariants"].values()) and report["ok"]
    assert len(report["faults"]) == 13
    for fault in report["faults"]:
        assert fault["recovered_ms"] is not None and fault["recovered_ms"] >= 0, fault
    # the crash with respawn: the ring is whole again only once the new process has joined
    assert report["faults"][0]["recovered_ms"] > 100
    assert report["commands_judged_by"] == "ledger" and report["commands"]["sent"] > 100
    # the test's own judge reads the same ledgers: nothing lost, twice taken or made up
    verdict = judge_ledgers(ledgers)
    assert verdict.ok, str(verdict)
    assert verdict.acked > 100 and len(verdict.incarnations) == 6  # five probes and main's second
    # the same scenario and seed: the very same frames and the same report
    _, again = run_scenario(tmp_path, "again", "--chaos", str(scenario), "--seed", "4")
    assert again["virtual"]["frames_sha256"] == report["virtual"]["frames_sha256"]
    assert again["faults"] == report["faults"] and again["commands"] == report["commands"]
    _, other = run_scenario(tmp_path, "other", "--chaos", str(scenario), "--seed", "5")
    assert other["virtual"]["frames_sha256"] != report["virtual"]["frames_sha256"]
    assert other["ok"]


def test_a_broken_invariant_exits_1_and_its_replay_file_gives_the_same_frames(tmp_path: Path):
    # respawn off: the crashed node cannot take the fault sent to it afterwards
    broken = yaml.safe_load(SCENARIO)
    broken["ring"]["respawn"] = False
    broken["faults"] = [
        {"at": 0.5, "node": "sonar", "kind": "crash"},
        {"at": 1.5, "node": "sonar", "kind": "delay", "value": 2},
    ]
    scenario = tmp_path / "broken.yaml"
    scenario.write_text(yaml.safe_dump(broken))
    done, report = run_scenario(tmp_path, "broken", "--chaos", str(scenario), "--seed", "11")
    assert done.returncode == 1
    assert report["invariants"]["no_injection_failed"] is False
    assert report["faults"][1]["errors"] and report["invariants"]["every_fault_recovered"]

    broken["sim"] = {"seed": 11, "bitrate": "2.5M", "frames_sha256": report["virtual"]["frames_sha256"]}
    replay = tmp_path / "replay.yaml"
    replay.write_text(yaml.safe_dump(broken))
    done, again = run_scenario(tmp_path, "replayed", "--replay", str(replay))
    assert done.returncode == 1  # the failure again
    assert again["replay"] == {
        "recorded_frames_sha256": report["virtual"]["frames_sha256"],
        "same_frames": True,
    }
    text = sim("--replay", str(replay), "--quiet")
    assert "replayed exactly: the same frames as the recorded run" in text.stdout

    broken["sim"]["frames_sha256"] = "0" * 64  # a recording this run does not give
    replay.write_text(yaml.safe_dump(broken))
    text = sim("--replay", str(replay), "--quiet")
    assert text.returncode == 1 and "NOT the recorded run" in text.stdout


def test_a_campaign_runs_seeds_on_two_processes_and_sums_what_they_did(tmp_path: Path):
    done = sim("--random", "3..6", "--duration", "12", "--jobs", "2", "--out", str(tmp_path), "--json", "-")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["seeds"] == 4 and result["failed"] == [] and result["jobs"] == 2
    assert result["simulated_s"] >= 4 * 12 and result["faults"] > 4
    assert result["commands"]["sent"] > 0 and result["commands"]["lost"] == 0
    assert result["commands"]["duplicated"] == 0
    assert not list(tmp_path.glob("sim-seed*.yaml"))  # only failures are written


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--random", "5..2"], "--random 5..2: seeds within"),
        (["--random", "x"], "--random x: expected seeds"),
        (["--random", "1..2", "--kinds", "crash,melt"], "--kinds: unknown operation 'melt'"),
        (["--random", "1..2", "--out", "/nonexistent/dir"], "--out /nonexistent/dir: no such directory"),
        (["--random", "1..2", "--seed", "3"], "--seed does not go with --random"),
        (["--chaos", "scenarios/compound.yaml", "--random", "1"], "give one of --chaos, --random, --replay"),
        (["--chaos", "scenarios/compound.yaml", "--fault", "crash:20@1"], "--fault does not go with --chaos"),
        (["--chaos", "scenarios/compound.yaml", "--bitrate", "max"], "--bitrate max has no wire time"),
        (["--replay", "scenarios/compound.yaml"], "no sim: section"),
        (["--chaos", "no-such-file.yaml"], "no-such-file.yaml"),
    ],
)
def test_bad_input_gets_one_line_and_exit_code_2(args: list[str], says: str):
    done = sim(*args)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert says in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_faults_that_land_alone_recover_within_the_timing_model(tmp_path: Path):
    """A lost token, a frozen node and a crash with nothing to restart it, each alone: the ring
    in virtual time recovers within what the ring's constants allow (tokenring bench --sim's
    model), whatever the seed."""
    scenario = tmp_path / "alone.yaml"
    scenario.write_text(
        """
ring: {nodes: all, respawn: false, workload: probe}
settle: 2.0
faults:
  - {at: 1.0, node: motor, kind: lose}
  - {at: 3.0, node: sonar, kind: hang}
  - {at: 5.0, node: sonar, kind: resume}
  - {at: 7.0, node: copro, kind: crash}
  - {at: 9.0, node: main, kind: lose}
"""
    )
    for seed in ("1", "8"):
        done, report = run_scenario(tmp_path, f"alone{seed}", "--chaos", str(scenario), "--seed", seed)
        assert done.returncode == 0, done.stdout
        modelled = [f for f in report["faults"] if "model_ms" in f]
        assert [f["kind"] for f in modelled] == ["lose", "hang", "crash", "lose"]
        assert report["timing_model"] == {"judged": 4, "within": 4}, modelled
        lose = modelled[0]
        # the lost-token timer of eight nodes at 2.5 Mbit/s: ARCNET's 840 ms, give or take a round
        assert 800 <= lose["recovered_ms"] <= 900 and lose["model_ms"][0] <= 840 <= lose["model_ms"][1]


def test_programs_downloaded_through_the_faults_install_exactly_what_was_sent(tmp_path: Path):
    """ring.downloads: main's system layer moves programs into the others all along, through a
    lost token, corruption, a crash, a hang and a cut; what completed is installed byte for byte
    (the harness compares the target's installed digest with the sent bytes' own, apart from the
    system layer's verification), and once the faults are over a download into every node
    succeeds."""
    scenario = tmp_path / "downloads.yaml"
    scenario.write_text(
        """
ring: {nodes: all, respawn: true, workload: probe, downloads: true}
settle: 2.0
faults:
  - {at: 1.0, node: motor, kind: lose}
  - {at: 2.0, node: sonar, kind: corrupt, value: 0.3}
  - {at: 3.0, node: sonar, kind: clear}
  - {at: 3.5, node: copro, kind: crash}
  - {at: 5.0, node: compass, kind: hang}
  - {at: 6.0, node: compass, kind: resume}
  - {at: 6.5, node: all, kind: partition, value: "main,motor,sonar|compass,copro,map,lcd,charger"}
  - {at: 7.5, node: all, kind: heal}
"""
    )
    done, report = run_scenario(tmp_path, "downloads", "--chaos", str(scenario), "--seed", "3")
    assert done.returncode == 0, done.stdout
    downloads = report["downloads"]
    assert downloads["attempted"] >= 8 and downloads["completed"] >= 5, downloads
    assert downloads["after_the_faults"] == {str(i): "ok" for i in (20, 30, 40, 50, 60, 70, 80)}
    for name in (
        "no_download_installed_other_bytes",
        "no_download_stuck",
        "downloads_succeed_after_the_faults",
    ):
        assert report["invariants"][name], name

    # the same file on real processes is refused, naming why (the downloads are virtual-time only)
    real = subprocess.run(
        [*TOKENRING, "chaos", str(scenario)], capture_output=True, text=True, timeout=120, cwd=REPO
    )
    assert real.returncode == 2 and "ring.downloads runs in virtual time only" in real.stderr
