"""System commands and program download on the in-memory ring, in virtual time: the real node and
system-layer code on a simulated clock, deterministic (tests.support.memring.in_virtual_time)."""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.memring import MemoryRing, in_virtual_time, wait_for
from tokenring import runtime
from tokenring.node.store import ProgramStore
from tokenring.node.system.layer import SystemLayer
from tokenring.node.system.vocabulary import State, Status, SystemCommandError

PROGRAM = """
from tokenring import UserProgram


class Program(UserProgram):
    module = "{module}"
    version = {version}

    def run(self):
        if self.os.name == "motor":
            self.os.publish().write(x_mm={version})
        while self.running:
            self.sleep(0.01)

    def report(self):
        return {{"version": self.version}}
"""

RAISES = """
from tokenring import UserProgram


class Program(UserProgram):
    def setup(self):
        raise ZeroDivisionError("division by zero in setup")
"""


def program(version: int, module: str = "motor") -> bytes:
    return PROGRAM.format(module=module, version=version).encode()


@contextlib.contextmanager
def system_ring(tmp_path: Path) -> Iterator[tuple[MemoryRing, dict[int, SystemLayer]]]:
    """main, motor and sonar with their system layers (stores under ``tmp_path``), at ARCNET's
    2.5 Mbit/s: the tests run in virtual time, where the wire's time moves the clock."""
    r = MemoryRing([10, 20, 30], bitrate=2.5e6)
    layers = {
        i: SystemLayer(node, store=ProgramStore(tmp_path / node.name, node.name)).install()
        for i, node in r.nodes.items()
    }
    try:
        r.wait_rounds(10)
        yield r, layers
    finally:
        for layer in layers.values():
            layer.close()
        r.close()


def download(layer: SystemLayer, target: int, source: bytes, stamp: int = 1000, start: bool = True):
    return layer.execute(layer.download_steps(target, source, stamp, start=start), "download", 10.0)


@in_virtual_time()
def test_scan_and_config_of_bare_nodes(tmp_path):
    with system_ring(tmp_path) as (_r, layers):
        main = layers[10]
        assert main.scan() == [10, 20, 30]
        configs = main.configs([10, 20, 30])
        assert [c["name"] for c in configs.values()] == ["main", "motor", "sonar"]
        assert all(c["state"] == "NONE" and c["stamp_ms"] == 0 for c in configs.values())


@in_virtual_time()
def test_download_installs_starts_and_restores_the_user_area(tmp_path):
    with system_ring(tmp_path) as (r, layers):
        main, motor = layers[10], layers[20]
        # main's data channel lies in the system data window: it must survive the download
        main_out = r.nodes[10].publish()
        main_out.write(steps_done=4321, stamp_ms=99)
        reader = r.nodes[30].subscribe("main.data")
        wait_for(lambda: reader["steps_done"] == 4321, 2, "main.data at sonar")
        source = program(1) + b"# padding\n" * 60
        tx = download(main, 20, source)
        chunks = sum(1 for s in tx.steps if s.code == main.DATA)
        assert motor.stats.chunks_received == chunks > 5
        assert motor.stats.downloads_verified == 1 and motor.stats.installs == 1
        wait_for(lambda: r.nodes[20].program is not None and r.nodes[20].program.version == 1, 2, "v1 runs")
        config = main.configs([20])[20]
        assert config["stamp_ms"] == 1000 and config["size"] == len(source)
        assert config["sha256"] == hashlib.sha256(source).hexdigest()[:16]
        assert config["state"] == "RUNNING"
        r.wait_rounds(3)
        assert reader["steps_done"] == 4321 and reader["stamp_ms"] == 99
        # the store survives the node: a new layer on the same directory has the program
        stored = ProgramStore(tmp_path / "motor", "motor").load()
        assert stored is not None and stored.source == source and stored.stamp_ms == 1000


@in_virtual_time()
def test_user_channels_pause_while_a_system_command_is_active(tmp_path):
    with system_ring(tmp_path) as (r, layers):
        main = layers[10]
        out = r.nodes[20].publish()
        reader = r.nodes[30].subscribe("motor.data")
        out.write(x_mm=1)
        wait_for(lambda: reader["x_mm"] == 1, 2, "x_mm at sonar")
        tx = main.submit(main.download_steps(20, program(2) * 20, 5, compress=False), "long")
        wait_for(lambda: tx.index > 3, 2, "download under way")
        out.write(x_mm=2)
        visits = reader.visits
        r.wait_rounds(5)
        assert not tx.done.is_set()
        assert reader["x_mm"] == 1 and reader.visits == visits  # paused everywhere
        tx.done.wait(10)
        assert tx.ok, tx.error
        wait_for(lambda: reader["x_mm"] == 2, 2, "channels resume")


@in_virtual_time()
def test_corrupted_chunk_is_rejected_and_the_old_program_keeps_running(tmp_path):
    with system_ring(tmp_path) as (r, layers):
        main, motor = layers[10], layers[20]
        download(main, 20, program(1))
        wait_for(lambda: r.nodes[20].program is not None, 2, "v1 runs")
        old = r.nodes[20].program
        motor.corrupt_chunk = 3
        with pytest.raises(SystemCommandError, match="CORRUPT") as info:
            download(main, 20, program(2), stamp=2000)
        assert info.value.node == 20 and info.value.status == Status.CORRUPT
        assert motor.stats.downloads_rejected == 1
        assert r.nodes[20].program is old and old.running
        assert main.configs([20])[20]["stamp_ms"] == 1000
        # and the next, clean download goes through
        download(main, 20, program(3), stamp=3000)
        wait_for(lambda: r.nodes[20].program is not old, 2, "v3 replaces v1")
        assert r.nodes[20].program.version == 3


@in_virtual_time()
def test_too_large_a_program_is_refused_before_any_chunk(tmp_path):
    with system_ring(tmp_path) as (_r, layers):
        main, motor = layers[10], layers[20]
        motor.capacity = 1000
        with pytest.raises(SystemCommandError, match="REFUSED: accepts up to 1000 bytes"):
            download(main, 20, program(1) + b"#" * 2000)
        assert motor.stats.chunks_received == 0 and motor.installed is None


@in_virtual_time()
def test_a_program_for_another_module_or_that_does_not_load_is_rejected(tmp_path):
    with system_ring(tmp_path) as (_r, layers):
        main = layers[10]
        with pytest.raises(SystemCommandError, match="LOAD_ERROR: program of 'sonar'"):
            download(main, 20, program(1, module="sonar"))
        with pytest.raises(SystemCommandError, match="LOAD_ERROR: 1: syntax error"):
            download(main, 20, b"def broken(:\n")
        assert layers[20].installed is None
        wait_for(lambda: main.errors, 3, "the whole message through ARCNET_ERROR")
        assert main.errors[-1]["text"] == "motor.py:1: syntax error: invalid syntax"
        assert main.errors[-1]["about"] == "ARCNET_DOWNLOAD_TERMINATED"


@in_virtual_time()
def test_a_program_that_raises_on_start_is_reported_through_arcnet_error(tmp_path):
    with system_ring(tmp_path) as (r, layers):
        main = layers[10]
        with pytest.raises(SystemCommandError, match="START_FAILED: ZeroDivisionError"):
            download(main, 30, RAISES.encode())
        wait_for(lambda: main.errors, 3, "an ARCNET_ERROR at main")
        error = main.errors[-1]
        assert error["node"] == 30 and error["name"] == "sonar"
        assert error["text"] == "ZeroDivisionError: division by zero in setup"
        assert layers[30].program_state() == State.FAILED
        r.wait_rounds(5)  # the node stays on the ring
        assert main.scan() == [10, 20, 30]


@in_virtual_time()
def test_start_and_stop_system_and_single_programs(tmp_path):
    with system_ring(tmp_path) as (r, layers):
        main = layers[10]
        download(main, 20, program(1), start=False)
        download(main, 30, program(1, module="sonar"), start=False)
        assert r.nodes[20].program is None
        assert main.broadcast(main.START_SYSTEM, "start") == [20, 30]  # main has no program
        wait_for(lambda: all(layers[i].program_state() == State.RUNNING for i in (20, 30)), 2, "started")
        assert main.broadcast(main.STOP_SYSTEM, "stop") == [10, 20, 30]
        wait_for(lambda: all(r.nodes[i].program is None for i in (20, 30)), 2, "stopped")
        main.execute([main.start_step(30)], "start sonar")
        assert layers[30].program_state() == State.RUNNING and r.nodes[20].program is None
        main.execute([main.stop_step(30)], "stop sonar")
        assert r.nodes[30].program is None


@in_virtual_time()
def test_download_survives_token_loss(tmp_path):
    with system_ring(tmp_path) as (r, layers):
        main, motor = layers[10], layers[20]
        source = program(7) + b"# padding\n" * 100
        tx = main.submit(main.download_steps(20, source, 7, start=True, compress=False), "lossy")
        node = r.nodes[30]
        lost = []

        def lose_some(frame, _=None):
            if tx.index in (10, 40) and len(lost) < 2 and tx.index not in lost:
                lost.append(tx.index)
                return True  # swallowed: the ring regenerates the token
            return False

        node.rx_fault = lose_some
        assert tx.done.wait(20), tx.progress()
        node.rx_fault = None
        assert tx.ok, tx.error
        assert len(lost) == 2
        assert motor.installed is not None and motor.installed.source == source
        wait_for(lambda: r.nodes[20].program is not None and r.nodes[20].program.version == 7, 2, "v7")


@in_virtual_time()
def test_orphaned_command_of_a_dead_issuer_is_cleared(tmp_path):
    with system_ring(tmp_path) as (r, layers):
        motor = layers[20]
        tx = motor.submit(motor.download_steps(30, program(1, "sonar") * 30, 5, compress=False), "from motor")
        wait_for(lambda: tx.index > 2, 2, "motor's download under way")
        layers[20].close()
        r.nodes[20].system_handler = None
        r.nodes[20].close()  # the issuer dies with its command in the token
        out = r.nodes[30].publish()
        reader = r.nodes[10].subscribe("sonar.data")
        out.write(sweep=77)
        wait_for(lambda: reader["sweep"] == 77, 5, "user channels resume after the orphan is cleared")
        assert layers[10].stats.orphans_cleared + layers[30].stats.orphans_cleared >= 1


@in_virtual_time()
def test_a_download_waits_out_a_target_the_ring_skipped_for_a_moment(tmp_path):
    # a loaded machine stalls the target for a few passes: its predecessor skips it and the
    # ring runs on without it; rounds that never visit the target must not fail the command
    with system_ring(tmp_path) as (r, layers):
        main, motor = layers[10], layers[20]
        source = program(8) + b"# padding\n" * 100
        tx = main.submit(main.download_steps(20, source, 8, start=True, compress=False), "stalled target")
        wait_for(lambda: tx.index > 2, 2, "the download under way")
        r.freeze(20)
        wait_for(lambda: 20 in r.nodes[10].membership.excluded, 3, "node 10 to skip the stalled target")
        r.wait_rounds(30, node_id=10)  # well past the unacknowledged rounds a visited target may take
        assert not tx.done.is_set(), tx.error
        r.freeze(20, False)
        assert tx.done.wait(20), tx.progress()
        assert tx.ok, tx.error
        assert motor.installed is not None and motor.installed.source == source


@in_virtual_time()
def test_a_command_to_a_target_skipped_for_good_fails_naming_it(tmp_path):
    with system_ring(tmp_path) as (r, layers):
        main = layers[10]
        tx = main.submit([main.start_step(20)], "start a hung node")
        r.freeze(20)
        try:
            wait_for(lambda: 20 in r.nodes[10].membership.excluded, 3, "node 10 to skip the hung target")
            assert tx.done.wait(20), tx.progress()
            assert tx.error == "node 20 is skipped by the ring (not answering for 3 s)"
        finally:
            r.freeze(20, False)


@in_virtual_time()
def test_each_skip_of_the_target_gets_its_own_wait(tmp_path, monkeypatch):
    # a long download whose target is skipped twice, the second time long after the first: the
    # first skip's wait must not carry over (the clock jumps 10 s between them, as a long
    # download would take)
    with system_ring(tmp_path) as (r, layers):
        offset = [0.0]
        main, motor = layers[10], layers[20]
        monkeypatch.setattr(
            main, "_clock", lambda: runtime.current().monotonic() + offset[0]
        )  # the issuer's clock
        source = program(9) + b"# padding\n" * 3000  # 1000 chunks: still going after skip 1
        tx = main.submit(main.download_steps(20, source, 9, start=True, compress=False), "skipped twice")
        wait_for(lambda: tx.index > 2, 2, "the download under way")
        for skip in (1, 2):
            r.freeze(20)
            wait_for(lambda: 20 in r.nodes[10].membership.excluded, 3, f"skip {skip} of the target")
            r.wait_rounds(30, node_id=10)
            assert not tx.done.is_set(), (skip, tx.error)
            index = tx.index
            r.freeze(20, False)
            wait_for(
                lambda i=index: tx.index > i or tx.done.is_set(), 5, f"the target back after skip {skip}"
            )
            offset[0] += 10.0
        assert tx.done.wait(20), tx.progress()
        assert tx.ok, tx.error
        assert motor.installed is not None and motor.installed.source == source


@in_virtual_time()
def test_a_program_that_fails_is_counted_even_when_its_rollback_stops_it_first():
    """The rollback a failure starts stops the failed program (its ``stop_requested``); when that
    wins the race to the check, the failure must still reach the launcher (exit code 1)."""
    from tokenring import UserProgram

    class Fails(UserProgram):
        module = "motor"

        def run(self) -> None:
            raise ZeroDivisionError("motor divided by zero")

    ring = MemoryRing([10, 20])
    motor = ring.nodes[20]
    failures: list[tuple[str, str]] = []
    # the rollback, run before the check as the other thread may: it stops the failed program
    motor.on_program_error = lambda: motor.program.stop_requested.set()
    motor.on_program_failed = lambda _program, phase, error: failures.append((phase, error))
    try:
        motor.start_program(Fails)
        wait_for(lambda: motor.program_error, 5, "the program to fail")
        wait_for(lambda: failures, 5, "the failure to be reported")
        assert failures == [("run", "ZeroDivisionError: motor divided by zero")]
    finally:
        ring.close()
