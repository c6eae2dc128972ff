"""A recording onto a full disk (a small tmpfs) costs only the recording (issue 52): one line
naming the file, no traceback, a non-zero exit code, no ``FILE.part`` left; what was written
whole before the disk filled is kept as ``FILE`` (a recording without an index, as a killed
recorder leaves it), readable as any recording is. Under ``up`` the dead recorder is named and
the run does not end with exit code 0."""

from __future__ import annotations

import contextlib
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.processes import TOKENRING, run_tokenring
from tests.support.ringutil import tap, wait_ring
from tests.support.smalldisk import listing, small_disk
from tokenring.observe.recording import open_recording

#: a disk that a two-node ring's frames fill within seconds
DISK = 128 * 1024


@contextlib.contextmanager
def two_nodes(procs, ring: str, endpoint: str) -> Iterator[None]:
    """A two-node ring for the block; stopped (SIGTERM, by PID) after it."""
    launcher = procs.tokenring(
        "up", "--ring", ring, "--listen", endpoint, "--nodes", "main,motor", "--no-world", "--no-programs"
    )  # fmt: skip
    try:
        with tap(endpoint) as session:
            wait_ring(session, ring, [10, 20])
        yield
    finally:
        launcher.send_signal(signal.SIGTERM)
        launcher.wait(timeout=60)


def what_is_kept(disk: Path, name: str) -> None:
    """Only ``name`` (or nothing) is on the disk, and a file there is a readable recording."""
    left = listing(disk)
    assert left in ([], [name]), left  # no FILE.part, no temporary file
    if left:
        recording = open_recording(disk / name)
        assert not recording.indexed and sum(count for _, _, count in recording.channels.values()) > 0


def one_error_line(stderr: str, *needles: str) -> None:
    lines = stderr.strip().splitlines()
    assert "Traceback" not in stderr and len(lines) == 1, stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


@pytest.mark.slow
def test_record_onto_a_full_disk_stops_with_one_line(procs, ring_name, endpoint, tmp_path):
    with two_nodes(procs, ring_name, endpoint), small_disk(tmp_path / "disk", DISK) as disk:
        target = disk / "run.mcap"
        # --duration is only the hang guard: the full disk ends the recording long before
        result = run_tokenring(
            "record", str(target), "--ring", ring_name, "-e", endpoint, "--duration", "120", "--quiet",
            timeout=180,
        )  # fmt: skip
        assert result.returncode == 1, (result.returncode, result.stdout, result.stderr)
        one_error_line(result.stderr, str(target), "cannot write the recording: No space left on device")
        what_is_kept(disk, "run.mcap")


@pytest.mark.slow
def test_sniff_write_onto_a_full_disk_stops_with_one_line(procs, ring_name, endpoint, tmp_path):
    with two_nodes(procs, ring_name, endpoint), small_disk(tmp_path / "disk", DISK) as disk:
        target = disk / "frames.mcap"
        result = subprocess.run(  # the decoded frames on stdout are not what is judged
            [*TOKENRING, "sniff", "--write", str(target), "--ring", ring_name, "-e", endpoint, "--duration", "120"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=180,
        )  # fmt: skip
        assert result.returncode == 1, (result.returncode, result.stderr)
        one_error_line(result.stderr, f"--write {target}", "No space left on device")
        what_is_kept(disk, "frames.mcap")


@pytest.mark.slow
@pytest.mark.parametrize("verb", ["sniff", "record"])
def test_a_pcapng_capture_onto_a_full_disk_stops_with_one_line(verb, procs, ring_name, endpoint, tmp_path):
    """``sniff --write FILE.pcapng`` and ``record --pcap``: the capture keeps every block that
    fitted, as ``FILE`` (tshark and ``sniff --read`` read it), and says so in one line, exit 1."""
    from tokenring.observe.pcapng import open_pcapng

    with two_nodes(procs, ring_name, endpoint), small_disk(tmp_path / "disk", DISK) as disk:
        target = disk / "frames.pcapng"
        option = "--write" if verb == "sniff" else "--pcap"
        result = subprocess.run(  # the decoded frames on stdout are not what is judged
            [*TOKENRING, verb, option, str(target), "--ring", ring_name, "-e", endpoint, "--duration", "120",
             *(["--quiet"] if verb == "record" else [])],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=180,
        )  # fmt: skip
        assert result.returncode == 1, (result.returncode, result.stderr)
        one_error_line(
            result.stderr, str(target), "cannot write the capture: No space left on device", "frames"
        )
        assert listing(disk) == ["frames.pcapng"]
        capture = open_pcapng(target)
        assert capture.frames > 50 and len(list(capture)) == capture.frames
        assert target.stat().st_size > DISK - 8 * 4096  # what fitted was kept, nearly the whole disk


@pytest.mark.slow
def test_up_names_a_recording_the_disk_ended_and_exits_1(procs, ring_name, endpoint, tmp_path):
    with small_disk(tmp_path / "disk", DISK) as disk:
        target = disk / "run.mcap"
        result = run_tokenring(
            "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--no-world",
            "--no-programs", "--record", str(target), "--duration", "20",
            timeout=180,
        )  # fmt: skip
        assert result.returncode == 1, (result.returncode, result.stdout[-3000:])
        assert "Traceback" not in result.stdout + result.stderr, result.stdout[-3000:]
        failed = [line for line in result.stdout.splitlines() if "cannot write the recording" in line]
        assert len(failed) == 1 and str(target) in failed[0] and "No space left on device" in failed[0]
        assert any(line.split("|")[0].strip() == "up" and "watch" in line for line in result.stdout.splitlines()
                   if "exited" in line or "died" in line), result.stdout[-3000:]  # fmt: skip
        what_is_kept(disk, "run.mcap")
