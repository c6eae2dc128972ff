"""The interleaved own share (``tokenring bench --interleave``): both rings in the same seconds,
one frozen while the other runs."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from tests.support.processes import REPO
from tokenring.perf.interleaved_pairs import since_resume, summarize, window_rounds

TOKENRING = [sys.executable, "-m", "tokenring"]


def test_a_bare_window_keeps_the_rounds_between_its_resume_and_freeze_after_the_settle():
    stamps = [0.5, 0.9, 10.0, 10.1, 10.3, 10.6, 11.0, 20.0]  # 10.0 is the first arrival after the resume
    assert window_rounds(stamps, 9.8, 11.2, settle=0) == pytest.approx([0.1, 0.2, 0.3, 0.4])
    assert window_rounds(stamps, 9.8, 11.2, settle=2) == pytest.approx([0.3, 0.4])
    assert window_rounds(stamps, 12.0, 13.0, settle=0) == []


def test_a_ring_window_starts_after_the_round_that_spans_the_freeze():
    # the ring ran 0.1 s before its rounds were asked for; the 0.62 s round spans the freeze
    rounds = [0.02, 0.03, 0.62, 0.05, 0.021, 0.022, 0.023]
    assert since_resume(rounds, 0.1, settle=0) == pytest.approx([0.021, 0.022, 0.023])
    assert since_resume(rounds, 0.2, settle=1) == pytest.approx([0.021, 0.022, 0.023])
    # a round slower than half the freeze but within the window is kept, not taken for the freeze
    assert since_resume([0.02, 0.7, 0.02, 0.35, 0.03], 0.45, settle=0) == pytest.approx([0.02, 0.35, 0.03])
    # no round since the resume: nothing is measured
    assert since_resume([0.02, 0.9], 0.5, settle=0) == []
    assert since_resume([0.1, 0.1], 0.25, settle=3) == []


def test_a_pair_sets_the_ring_window_against_the_bare_windows_either_side():
    # 4 nodes; ring medians 1.2 and 1.0 ms; bare 1.0, 1.2, 0.8 ms: a bare ring drifting both ways
    ring = [[0.0012, 0.0012, 0.0013], [0.0010, 0.0009, 0.0010]]
    bare = [[0.0010, 0.0010], [0.0012, 0.0012], [0.0008, 0.0008]]
    steal = [1.0, 2.0, 12.0, 0.0, 3.0]  # bare, ring, bare, ring, bare: the middle bare window spoiled
    record = summarize(4, "peer", 0.6, 2, ring, bare, steal, warnings=0)
    # pair 0: 1.2 - (1.0 + 1.2) / 2 = 0.1 ms over 4 nodes = 25 µs; pair 1: 1.0 - 1.0 = 0
    assert record["pair_shares_us"] == pytest.approx([25.0, 0.0])
    # a bare figure is the worse of its two windows': both pairs share the spoiled window
    assert record["pair_steal_pct"] == [(2.0, 12.0), (0.0, 12.0)]
    assert record["own_share_all_us"]["mean"] == pytest.approx(12.5) and record["own_share_all_us"]["n"] == 2
    assert record["own_share_us"]["n"] == 0  # no pair within 10 % steal
    assert record["ring_rounds"] == [3, 3] and record["bare_rounds"] == [2, 2, 2]
    # the ring's six rounds sorted: 0.9 1.0 1.0 1.2 1.2 1.3 ms; rank 0.99 * 5 = 4.95: 1.2 + 0.95 * 0.1
    assert record["pooled_p99_ms"]["ring"] == pytest.approx(1.295)
    # no ring window within the limit; the calm bare windows are the first and the last (1 and 3 %)
    assert record["calm_p99_ms"]["ring"] is None and record["calm_p99_ms"]["bare"] == pytest.approx(1.0)


def test_a_pair_without_rounds_in_any_of_its_windows_is_left_out():
    ring = [[0.001], [], [0.001]]
    bare = [[0.001], [0.001], [], [0.001]]
    record = summarize(2, "peer", 0.6, 2, ring, bare, [0.0] * 7, warnings=0)
    # pair 1 had no ring rounds, pair 2 no bare rounds before it: only pair 0 is usable
    assert record["pairs"] == 3 and record["pairs_usable"] == 1
    assert record["pair_shares_us"] == [0.0, None, None]


def test_windows_that_do_not_alternate_are_refused():
    with pytest.raises(ValueError, match="bare window before and after"):
        summarize(2, "peer", 0.6, 2, [[0.001]], [[0.001]], [0.0, 0.0, 0.0], warnings=0)


@pytest.mark.slow
def test_both_rings_take_turns_without_the_frozen_ring_noticing(tmp_path):
    out = tmp_path / "interleave.json"
    pairs, window = 4, 0.5
    command = [*TOKENRING, "bench", "--nodes", "4", "--topology", "peer"]
    command += ["--interleave", str(pairs), "--window", str(window), "--json", str(out)]
    result = subprocess.run(
        command,
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )
    assert result.returncode == 0, result.stderr
    record = json.loads(out.read_text())
    assert record["pairs"] == pairs and record["pairs_usable"] == pairs
    assert len(record["bare_rounds"]) == pairs + 1
    # a 4-node ring goes round in about a millisecond: every window held many rounds, and the
    # ring's counted rounds fit in its window (the round spanning the freeze was left out)
    assert min(record["ring_rounds"]) >= 20 and min(record["bare_rounds"]) >= 20
    # (with the round that spans a freeze, ~0.5 s, a window would hold ~1 s of rounds)
    assert all(0 < measured <= 1.5 * window for measured in record["ring_measured_s"])
    # no node woke to find itself frozen (it would ask to rejoin); a watchdog due just before a
    # resume may regenerate the token, rarely (0-2 times in 100 pairs)
    assert not any("frozen" in line for line in record["ring_warning_lines"])
    assert record["ring_warnings"] == len(record["ring_warning_lines"]) <= 1
    interval = record["own_share_all_us"]
    assert interval["n"] == pairs and interval["lo"] <= interval["mean"] <= interval["hi"]
    # what a person reads: both rings' medians and tails, the own share over the calm pairs
    assert "µs per hop" in result.stdout and "within 10 % steal" in result.stdout
    rows = {
        line.split()[0]: line.split()
        for line in result.stdout.splitlines()
        if line.startswith(("tokenring ", "bare "))
    }
    assert float(rows["tokenring"][1]) == pytest.approx(record["pooled_median_ms"]["ring"], abs=0.001)
    assert rows["bare"][-1] == str(sum(record["bare_rounds"]))
    for pid in record["pids"]["ring"] + record["pids"]["bare"]:
        assert not os.path.exists(f"/proc/{pid}") or "zombie" in Path(f"/proc/{pid}/status").read_text()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--interleave", "10", "--window", "5"], "--window must be 0.05..1 s"),
        (["--interleave", "10", "--nodes", "300"], "--nodes must be 2..255"),
        (["--interleave", "1"], "--interleave takes 2..10000 pairs"),
        (["--interleave", "10", "--rounds", "500"], "--rounds belongs to separate runs"),
        (["--interleave", "10", "--repeat", "2"], "--repeat belongs to separate runs"),
        (["--interleave", "10", "--tap"], "--tap belongs to separate runs"),
        (["--interleave", "10", "--transport", "udp"], "--transport belongs to separate runs"),
        (["--interleave", "10", "--bitrate", "fast"], "bitrate"),
        (["--window", "0.5"], "--window sets the windows of --interleave"),
    ],
)
def test_values_it_cannot_measure_with_are_refused_in_one_line(args, says):
    result = subprocess.run(
        [*TOKENRING, "bench", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
    )
    assert result.returncode == 2 and says in result.stderr
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_an_existing_output_file_is_left_alone(tmp_path):
    out = tmp_path / "kept.json"
    out.write_text("{}")
    result = subprocess.run(
        [*TOKENRING, "bench", "--interleave", "10", "--json", str(out)],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert result.returncode == 2 and "exists" in result.stderr and out.read_text() == "{}"


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_ctrl_c_between_windows_ends_both_rings_frozen_or_not(procs):
    from tests.support.processes import wait_gone
    from tests.support.ringutil import processes, wait_until

    driver = procs.start(
        [*TOKENRING, "bench", "--nodes", "3", "--topology", "peer", "--interleave", "1000"],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        # as a shell's foreground job: one started in the background (`cmd &`, nohup) inherits
        # SIGINT ignored, and Python then raises no KeyboardInterrupt for it
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    said: list[str] = []
    begun = threading.Event()

    def read_stderr() -> None:  # read to the end: a full pipe would stall the driver or a ring
        for line in driver.stderr:
            said.append(line)
            if "pairs of" in line:  # the windows have begun: one ring frozen, the other running
                begun.set()
        begun.set()

    threading.Thread(target=read_stderr, daemon=True).start()
    assert begun.wait(120) and driver.poll() is None, "".join(said[-20:])
    children = [pid for pid, (ppid, _) in processes().items() if ppid == driver.pid]
    assert len(children) >= 6  # three bare processes, three nodes

    def frozen() -> list[int]:
        states = {pid: Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] for pid in children}
        return [pid for pid, state in states.items() if state == "T"]

    wait_until(frozen, timeout=60, what="the ring not measured to be frozen")
    driver.send_signal(2)  # SIGINT
    try:
        code = driver.wait(timeout=90)
    except subprocess.TimeoutExpired:
        heard = len(said)
        driver.send_signal(signal.SIGUSR1)  # the CLI prints every thread's stack
        with contextlib.suppress(AssertionError):  # no stacks: still fail with what it said
            wait_until(lambda: len(said) > heard + 3, 10, "the driver's stacks")
        pytest.fail(f"the driver did not stop within 90 s of Ctrl-C; it said: {''.join(said[-60:])}")
    assert code == 130, "".join(said[-20:])
    assert wait_gone(children, timeout=30) == []
