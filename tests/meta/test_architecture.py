"""The house's walls: the import contracts of pyproject.toml hold, a wrong arrow breaks them, and
the ring runs a system that is not a robot with no robot code loaded at all."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

from tests.support.processes import REPO, run_tokenring
from tests.support.ringutil import answering_launcher_pids, tap, wait_until

LINT = [
    sys.executable,
    "-c",
    "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())",
]
PINGPONG = REPO / "tests" / "pingpong"


def lint(cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(LINT, cwd=cwd, capture_output=True, text=True, timeout=300, env=env)


def test_the_wings_keep_their_contracts():
    result = lint(REPO)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 broken" in result.stdout, result.stdout
    # every contract of pyproject.toml was checked, none skipped
    contracts = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    assert len(contracts) >= 7 and result.stdout.count(" KEPT") == len(contracts), result.stdout


def test_a_wrong_arrow_fails_the_contracts(tmp_path: Path):
    """A copy of the tree where the ring imports the world, a node module the launcher and a
    program a module path behind the ring's face: the linter must name each and fail."""
    for name in ("tokenring", "modules", "bench"):
        shutil.copytree(
            REPO / name, tmp_path / name, ignore=shutil.ignore_patterns("__pycache__", "*.so", "results")
        )
    shutil.copy(REPO / "pyproject.toml", tmp_path / "pyproject.toml")
    wrong_arrows = {
        "tokenring/contract/keys.py": "import modules.world.sim",  # the ring imports the robot
        "tokenring/node/recovery.py": "import tokenring.host.launcher",  # a node imports the host side
        "modules/motor.py": "from tokenring.node.program import UserProgram",  # past the public face
    }
    for name, line in wrong_arrows.items():
        module = tmp_path / name
        module.write_text(module.read_text() + f"\n{line}  # a wrong arrow\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path))  # the copy, not the installed tree
    result = lint(tmp_path, env)
    assert result.returncode != 0, result.stdout
    assert "The ring knows nothing of the robot BROKEN" in result.stdout, result.stdout
    assert "tokenring.contract.keys -> modules.world.sim" in result.stdout, result.stdout
    assert "The ring's rooms are layered BROKEN" in result.stdout, result.stdout
    assert "tokenring.node.recovery -> tokenring.host.launcher" in result.stdout, result.stdout
    assert "The robot and the benchmarks import only the ring's public faces BROKEN" in result.stdout
    assert "modules.motor -> tokenring.node.program" in result.stdout, result.stdout
    assert "The ring ships without its benchmarks: tokenring never imports bench KEPT" in result.stdout


def test_the_bare_ring_loads_no_robot_code():
    env = dict(os.environ, TOKENRING_EXTENSIONS="")
    probe = (
        "import sys; from tokenring.cli.main import build_parser; parser, runners = build_parser(); "
        "print(sorted(runners)); print([m for m in sys.modules if m == 'modules' or m.startswith('modules.')])"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=env, timeout=60
    )
    assert result.returncode == 0, result.stderr
    verbs, loaded = result.stdout.strip().splitlines()
    assert loaded == "[]", loaded
    assert "'up'" in verbs and "'explore'" not in verbs and "'map'" not in verbs, verbs
    with_robot = run_tokenring("--help")
    assert with_robot.returncode == 0 and "explore" in with_robot.stdout and "replay" in with_robot.stdout


def test_an_unknown_extension_is_one_clear_line():
    env = dict(os.environ, TOKENRING_EXTENSIONS="robot,nosuch")
    for args in (["up", "--help"], ["--help"], ["explore", "1"]):  # where the extensions are loaded
        result = run_tokenring(*args, env=env)
        assert result.returncode == 2, result.stdout + result.stderr
        assert result.stderr.strip().splitlines() == [
            "tokenring: error: TOKENRING_EXTENSIONS: no extension named nosuch is installed"
        ], args
    # a ring verb whose options need no extension loads none
    assert run_tokenring("status", "--help", env=env).returncode == 0


def test_a_system_that_is_not_a_robot_runs_on_the_ring(procs, ring_name, endpoint, tmp_path):
    """Ping and pong, two programs of tests/pingpong, rally a ball over command channels on
    ``tokenring up`` with no extension: no world, no robot, the ring's runtime alone."""
    env = {"TOKENRING_EXTENSIONS": "", "PINGPONG_LOG": str(tmp_path)}
    output = tmp_path / "up.out"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--bitrate", "max",
        "--protocol", str(PINGPONG / "protocol.yaml"), "--programs", str(PINGPONG),
        env=env, stdout=output.open("w"),
    )  # fmt: skip
    log = tmp_path / "ping.log"

    def rallies() -> list[tuple[int, int]]:
        if not log.exists():
            return []
        return [
            tuple(map(int, line.split()))
            for line in log.read_text().splitlines()
            if line.count(" ") == 1 and line[0].isdigit()  # not "stale N" / "again N"
        ]

    with tap(endpoint) as session:
        procs.watch(
            wait_until(lambda: answering_launcher_pids(session, ring_name), 60, "the launcher to answer")
        )
        got = wait_until(lambda: len(rallies()) >= 30 and rallies(), 120, "30 rallies between ping and pong")
    launcher.send_signal(signal.SIGTERM)
    assert launcher.wait(30) == 0
    served = [n for n, _ in got]
    assert all(back == n + 1 for n, back in got), got  # pong returned every ball it was served
    assert all(nxt == back + 1 for (_, back), nxt in zip(got, served[1:], strict=False)), got
    # a stale answer only ever follows a ball served again: after a timeout, or a resend of one
    # transmitted but not acknowledged (the OS itself never hands a command over twice)
    notes = log.read_text().split()
    assert notes.count("stale") <= notes.count("again"), log.read_text()
    said = output.read_text()
    assert "starting 2 nodes (ping=10, pong=20)" in said and "world" not in said.lower(), said
