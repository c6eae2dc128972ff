"""``tokenring sim``: the same command and seed print the same hash of the whole frame stream;
bad input is one line and exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

from tests.support.processes import run_tokenring


def summary(tmp_path: Path, name: str, *args: str) -> dict:
    out = tmp_path / name
    result = run_tokenring("sim", *args, "--json", str(out), timeout=120)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    return json.loads(out.read_text())


def test_the_same_command_and_seed_give_the_same_frame_stream(tmp_path: Path) -> None:
    args = ("--nodes", "10,20,30,40", "--duration", "8", "--seed", "3")
    first, again = summary(tmp_path, "a.json", *args), summary(tmp_path, "b.json", *args)
    assert first["frames_sha256"] == again["frames_sha256"] and len(first["frames_sha256"]) == 64
    assert (first["frames"], first["visits"], first["simulated_s"]) == (
        again["frames"],
        again["visits"],
        again["simulated_s"],
    )
    # four hops of 512 bytes at 2.5 Mbit/s each round: 9.144 ms
    assert first["round_median_ms"] == 4 * 2.286
    assert first["regenerations"] == 1 and min(first["visits"].values()) > 0.7 * 8 / 0.009144
    longer = summary(tmp_path, "c.json", "--nodes", "10,20,30,40", "--duration", "9", "--seed", "3")
    assert longer["frames_sha256"] != first["frames_sha256"] and longer["frames"] > first["frames"]


def test_the_profile_slows_the_round_as_the_seed_robots_hardware_did(tmp_path: Path) -> None:
    wire = summary(tmp_path, "w.json", "--nodes", "10,20,30", "--duration", "5")
    robot = summary(tmp_path, "p.json", "--nodes", "10,20,30", "--duration", "5", "--profile", "arcnet")
    assert robot["round_median_ms"] > wire["round_median_ms"]


def test_bad_input_is_one_line_and_exit_2(tmp_path: Path) -> None:
    taken = tmp_path / "taken.json"
    taken.write_text("{}")
    for args, needle in [
        (["--bitrate", "max"], "--bitrate max has no wire time"),
        (["--nodes", "10"], "a ring needs two nodes at least"),
        (["--nodes", "10,nobody"], "unknown node 'nobody'"),
        (["--json", str(taken)], "--json"),
        (["--duration", "-3"], "--duration"),
    ]:
        result = run_tokenring("sim", *args, timeout=60)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and needle in lines[0], (args, result.stderr)
    assert taken.read_text() == "{}"


def test_faults_in_virtual_time_give_the_same_frames_for_the_same_command(tmp_path: Path) -> None:
    # the ring forms in about 1.7 simulated s (the nodes' boot, then main's lost-token timer)
    args = ("--nodes", "10,20,30,40", "--duration", "8", "--seed", "3")
    faults = ("--fault", "drop:30:0.5@2", "--fault", "clear@3", "--fault", "crash:20@4")
    faults += ("--fault", "hang:40@5", "--fault", "resume:40@6")
    first, again = summary(tmp_path, "a.json", *args, *faults), summary(tmp_path, "b.json", *args, *faults)
    assert first["frames_sha256"] == again["frames_sha256"] and first["faults"] == again["faults"]
    assert [f["fault"] for f in first["faults"]] == [
        "drop:30:0.5@2",
        "clear@3",
        "crash:20@4",
        "hang:40@5",
        "resume:40@6",
    ]
    assert all(f["recovered_s"] is not None for f in first["faults"])
    assert first["fault_counts"]["30"]["dropped"] > 0
    bad = run_tokenring("sim", "--fault", "crash:30@9", "--duration", "5", timeout=60)
    assert bad.returncode == 2 and "after the run's end" in bad.stderr.strip().splitlines()[0]
