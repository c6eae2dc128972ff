"""The exit-code rule of ``tokenring up`` (issue 52): a module program that failed — it raised
in ``setup()`` or in ``run()``, at any time of the run, or it does not load (a syntax error) —
makes the run's exit code 1, and the launcher says which program and why in one line. A run
whose programs are whole exits 0; ``load -s`` with a syntax error is bad input (exit 2).

Each run is two nodes, main and motor, motor running the program under test. A program that
fails mid-run waits for a trigger file, so the failure comes after the download's own watch of
the start, while the ring runs.
"""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import pytest

from tests.support.processes import run_tokenring
from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until

pytestmark = pytest.mark.slow

HEADER = "from tokenring import UserProgram\n\n\nclass Program(UserProgram):\n    module = 'motor'\n"
PROGRAMS = {
    "whole": HEADER + "    def run(self):\n        while self.running:\n            self.sleep(0.05)\n",
    "run": HEADER
    + "    def run(self):\n"
    + "        while self.running and not TRIGGER.exists():\n"
    + "            self.sleep(0.05)\n"
    + "        raise ZeroDivisionError('motor gave up mid-run')\n",
    "setup": HEADER + "    def setup(self):\n        raise ValueError('no motor driver')\n",
    "syntax": HEADER + "    def run(self)\n        pass\n",
}


def programs(tmp_path: Path, kind: str) -> tuple[Path, Path]:
    """A programs directory holding motor.py of ``kind``, and the trigger file it waits for."""
    directory = tmp_path / kind
    directory.mkdir()
    trigger = tmp_path / f"{kind}.trigger"
    source = PROGRAMS[kind]
    (directory / "motor.py").write_text(
        f"from pathlib import Path\nTRIGGER = Path({str(trigger)!r})\n{source}"
    )
    return directory, trigger


def run_up(procs, ring_name: str, endpoint: str, directory: Path, *options: str):
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--no-world",
        "--programs", str(directory), *options,
    )  # fmt: skip
    return launcher


def failures(session, ring_name: str) -> list[str]:
    try:
        return control(session, ring_name, "launcher", "status", timeout=1.0)["failures"]
    except AssertionError:  # not answering yet
        return []


def motor_program_state(session, ring_name: str) -> str | None:
    try:
        return control(session, ring_name, 20, "stats", timeout=1.0).get("program")
    except AssertionError:
        return None


def stopped(launcher: subprocess.Popen) -> tuple[int, list[str]]:
    """SIGTERM the launcher: its exit code and the lines it wrote from the launcher itself."""
    launcher.send_signal(signal.SIGTERM)
    output, _ = launcher.communicate(timeout=60)
    return launcher.returncode, [line for line in output.splitlines() if line.lstrip().startswith("up |")]


@pytest.mark.parametrize("download", [True, False], ids=["download", "no-download"])
def test_a_program_that_raises_in_run_mid_run_makes_the_exit_code_1(
    procs, ring_name, endpoint, tmp_path, download
):
    directory, trigger = programs(tmp_path, "run")
    launcher = run_up(procs, ring_name, endpoint, directory, *([] if download else ["--no-download"]))
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        wait_until(lambda: motor_program_state(session, ring_name), 60, "motor's program to run")
        assert failures(session, ring_name) == []
        trigger.touch()
        wait_until(lambda: failures(session, ring_name), 60, "the launcher to count the failure")
    code, lines = stopped(launcher)
    assert code == 1, lines
    said = [line for line in lines if "failed in run()" in line]
    assert len(said) == 1, lines
    assert (
        "motor.py on node motor (id 20)" in said[0] and "ZeroDivisionError: motor gave up mid-run" in said[0]
    )
    assert lines[-1].endswith("stopped (exit code 1)")


@pytest.mark.parametrize("download", [True, False], ids=["download", "no-download"])
def test_a_program_that_raises_in_setup_makes_the_exit_code_1(procs, ring_name, endpoint, tmp_path, download):
    directory, _ = programs(tmp_path, "setup")
    launcher = run_up(procs, ring_name, endpoint, directory, *([] if download else ["--no-download"]))
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        wait_until(lambda: failures(session, ring_name), 60, "the launcher to count the failure")
    code, lines = stopped(launcher)
    assert code == 1, lines
    said = [line for line in lines if "failed in setup()" in line]
    assert len(said) == 1 and "ValueError: no motor driver" in said[0], lines


def test_a_program_with_a_syntax_error_makes_the_exit_code_1_when_downloaded(
    procs, ring_name, endpoint, tmp_path
):
    directory, _ = programs(tmp_path, "syntax")
    launcher = run_up(procs, ring_name, endpoint, directory)
    with tap(endpoint) as session:
        # the download refuses the file before it sends anything; the ring goes on
        wait_ring(session, ring_name, [10, 20], timeout=120)  # (waits until the boot is over)
        procs.watch(launcher_pids(session, ring_name))
    launcher.send_signal(signal.SIGTERM)
    output, _ = launcher.communicate(timeout=60)
    assert launcher.returncode == 1, output[-3000:]
    said = [line for line in output.splitlines() if "loading the programs failed" in line]
    assert len(said) == 1 and "motor.py:8: syntax error" in said[0], output[-3000:]


def test_a_program_with_a_syntax_error_makes_the_exit_code_1_without_download(
    procs, ring_name, endpoint, tmp_path
):
    directory, _ = programs(tmp_path, "syntax")
    launcher = run_up(procs, ring_name, endpoint, directory, "--no-download")
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        wait_until(lambda: failures(session, ring_name), 60, "the launcher to count the failure")
    code, lines = stopped(launcher)
    assert code == 1, lines
    said = [line for line in lines if "failed to load" in line]
    assert len(said) == 1 and "motor.py:8: syntax error" in said[0], lines


def test_a_run_whose_programs_are_whole_exits_0(procs, ring_name, endpoint, tmp_path):
    directory, _ = programs(tmp_path, "whole")
    launcher = run_up(procs, ring_name, endpoint, directory)
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        wait_until(lambda: motor_program_state(session, ring_name), 60, "motor's program to run")
    code, lines = stopped(launcher)
    assert code == 0, lines
    assert not [line for line in lines if "failed" in line], lines


def test_load_single_with_a_syntax_error_is_bad_input(tmp_path):
    directory, _ = programs(tmp_path, "syntax")
    result = run_tokenring(
        "load", "-s", str(directory / "motor.py"), "--ring", "nobody", "-e", "tcp/127.0.0.1:9"
    )
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert "motor.py:8: syntax error" in lines[0]
