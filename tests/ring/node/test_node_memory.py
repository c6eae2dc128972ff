"""A node process imports what a node needs and nothing else (issue 23): no numpy, no plotting,
no package metadata, no OpenSSL (hashlib), no robot code and none of the other CLI verbs while it
runs no program;
its ``memory`` control verb says so. The 40 MB aim itself is the benchmark's (bench/suite.py):
tests hold no absolute sizes."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
import yaml

from tests.support.processes import REPO
from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until
from tokenring.contract.protocol import Protocol, load_protocol, parse_protocol

#: what a node that runs no program must not have imported (the test's own list)
NOT_IN_A_BARE_NODE = (
    "numpy", "matplotlib", "scipy", "ezdxf", "PIL", "importlib.metadata", "modules", "hashlib", "_hashlib",
)  # fmt: skip


def ring_at_full_speed(procs, ring_name: str, endpoint: str, nodes: str):
    """``tokenring up`` of ``nodes`` with no programs and no world, the token at bitrate max."""
    return procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", nodes,
        "--no-programs", "--no-world", "--bitrate", "max",
    )  # fmt: skip


def unwanted(modules: list[str]) -> list[str]:
    """The modules of ``modules`` a bare node must not hold: the list above (and submodules),
    and every CLI verb but ``node``."""
    bad = [m for m in modules if any(m == n or m.startswith(n + ".") for n in NOT_IN_A_BARE_NODE)]
    verbs = [
        m for m in modules if m.startswith("tokenring.cli.commands.") and m != "tokenring.cli.commands.node"
    ]
    return bad + verbs


@pytest.mark.slow
def test_nodes_without_programs_import_no_numpy_metadata_robot_code_or_other_verbs(
    procs, ring_name, endpoint
):
    # the robot's extension is installed: only lcd, which it gives a resident menu, loads it
    launcher = ring_at_full_speed(procs, ring_name, endpoint, "main,motor,lcd")
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 70], timeout=120)
        pids = launcher_pids(session, ring_name)
        procs.watch(pids)
        reports = {node: control(session, ring_name, node, "memory") for node in (10, 20, 70)}
        resident = control(session, ring_name, 70, "resident")
    launcher.send_signal(signal.SIGINT)
    assert launcher.wait(60) == 130
    assert resident["error"] is None  # lcd's menu runs: the launcher let it load the extension
    for node in (10, 20):
        report = reports[node]
        assert unwanted(report["modules"]) == [], (node, unwanted(report["modules"]))
        assert report["heavy"] == [], (node, report["heavy"])
        assert "tokenring.node.process" in report["modules"] and report["modules_count"] == len(
            report["modules"]
        )
    assert "modules" in reports[70]["modules"]  # the robot's resident menu is robot code
    for node, report in reports.items():
        # read from the kernel: a node's private pages are part of its resident ones, never all
        # of them (the interpreter's and Zenoh's code is shared with the other nodes)
        assert 0 < report["uss_kb"] < report["rss_kb"], (node, report)


def zenoh_shared_memory_kb(pid: int) -> int:
    """Resident kB of the Zenoh shared-memory segments (``/dev/shm/*.zenoh``) process ``pid`` maps,
    read from the kernel's smaps."""
    total, in_segment = 0, False
    with open(f"/proc/{pid}/smaps") as smaps:
        for line in smaps:
            fields = line.split()
            if fields and "-" in fields[0] and not fields[0].endswith(":"):  # a mapping's header
                in_segment = fields[-1].endswith(".zenoh")
            elif in_segment and fields[0] == "Rss:":
                total += int(fields[1])
    return total


@pytest.mark.slow
def test_a_node_that_sends_a_large_answer_maps_no_shared_memory_pool(procs, ring_name, endpoint):
    # Zenoh's default: a 16 MB pool, all of it resident, once a message over 3 KB goes to a
    # local peer; the round master's `rounds` answer (a float per round, up to 1024) is one
    launcher = ring_at_full_speed(procs, ring_name, endpoint, "main,motor")
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        pids = launcher_pids(session, ring_name)
        procs.watch(pids)
        rounds = wait_until(
            lambda: (r := control(session, ring_name, 10, "rounds")) and len(r) >= 1000 and r,
            120,
            "main to hold 1000 round times",
        )
        mapped = {pid: zenoh_shared_memory_kb(pid) for pid in pids}
    launcher.send_signal(signal.SIGINT)
    assert launcher.wait(60) == 130
    assert len(json.dumps(rounds)) > 3 * 1024  # an answer Zenoh would have sent through its pool
    # Zenoh's own small segments (12 kB each here) stay: only the 16 MB pool must not be there
    assert all(kb < 1024 for kb in mapped.values()), mapped


@pytest.mark.slow
def test_a_node_started_by_hand_loads_only_the_node_verb(procs, ring_name, endpoint):
    node = procs.tokenring(
        "--log-level", "warning", "node", "--id", "37", "--ring", ring_name, "--no-store",
        "--listen", endpoint,
        env={"TOKENRING_EXTENSIONS": ""},  # as the ring's own tests of a non-robot system run
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [37], timeout=120)
        report = control(session, ring_name, 37, "memory")
    node.send_signal(signal.SIGTERM)
    assert node.wait(30) == 0
    assert unwanted(report["modules"]) == [], unwanted(report["modules"])
    assert "tokenring.cli.commands.node" in report["modules"]


def test_the_protocol_is_read_as_yaml_once_then_from_its_cached_document(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    source = REPO / "protocol.yaml"
    first = load_protocol(source)
    cached = list((tmp_path / "tokenring").glob("protocol-*.json"))
    assert len(cached) == 1, cached
    again = load_protocol(source)
    assert isinstance(again, Protocol) and again == first
    assert again.channel("sonar.data").dtype == first.channel("sonar.data").dtype
    # a damaged copy is read past, and the text read as YAML again
    cached[0].write_text("{not json")
    assert load_protocol(source) == first
    # so is another text's document under this text's name (the name is a 32-bit checksum)
    other = source.read_text().replace("id: 80", "id: 83", 1)
    cached[0].write_text(json.dumps({"text": other, "document": yaml.safe_load(other)}))
    assert load_protocol(source) == first and 83 not in load_protocol(source).by_id
    # an edited file is a new document, not the cached one
    edited = tmp_path / "edited.yaml"
    edited.write_text(source.read_text().replace("id: 80", "id: 81", 1))
    assert 81 in load_protocol(edited).by_id and 81 not in first.by_id
    assert len(list((tmp_path / "tokenring").glob("protocol-*.json"))) == 2
    # text compiled from elsewhere (a recording's protocol, a test's) leaves nothing behind
    parse_protocol(edited.read_text().replace("id: 81", "id: 82", 1))
    assert len(list((tmp_path / "tokenring").glob("protocol-*.json"))) == 2


def test_a_cache_that_cannot_be_written_costs_nothing_but_the_yaml(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("")  # a file where the cache directory would be
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    source = REPO / "protocol.yaml"
    assert load_protocol(source).by_id[10].name == "main"
    assert not os.path.isdir(blocked)


def minor_faults(pid: int) -> int:
    """The process's minor page faults so far (/proc/PID/stat, field 10)."""
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[7])


@pytest.mark.slow
def test_a_visit_maps_no_memory_the_receiving_thread_keeps_its_python_state(procs, ring_name, endpoint):
    # Zenoh calls the token's callback on a thread Python does not know; were its Python thread
    # state made and deleted per call, CPython would map and unmap a 16 KB frame stack each
    # time and fault its pages in anew: a page fault or more per visit
    launcher = ring_at_full_speed(procs, ring_name, endpoint, "main,motor,sonar")
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30], timeout=120)
        pids = launcher_pids(session, ring_name)
        procs.watch(pids)
        motor = next(
            p for p in pids if "--id 20 " in Path(f"/proc/{p}/cmdline").read_text().replace("\0", " ")
        )
        first_visits = control(session, ring_name, 20, "visits")
        wait_until(lambda: control(session, ring_name, 20, "visits") >= first_visits + 300, 120, "300 visits")
        faults0, visits0 = minor_faults(motor), control(session, ring_name, 20, "visits")
        wait_until(lambda: control(session, ring_name, 20, "visits") >= visits0 + 3000, 180, "3000 visits")
        faults1, visits1 = minor_faults(motor), control(session, ring_name, 20, "visits")
    launcher.send_signal(signal.SIGINT)
    assert launcher.wait(60) == 130
    per_visit = (faults1 - faults0) / (visits1 - visits0)
    assert per_visit < 0.2, f"{faults1 - faults0} page faults in {visits1 - visits0} visits"


def test_a_benchmark_ring_of_generated_ids_boots_no_application():
    """``tokenring bench`` measures the ring alone: a generated ID that protocol.yaml names (70,
    the robot's lcd) must not boot the robot's resident menu (it made one node of every 64- and
    255-node benchmark ring 58 MB against the others' 37)."""
    from tokenring.perf.roundtrip import run_ring

    reports: dict[str, dict] = {}

    def on_ready(session, ring: str) -> None:
        reports["lcd"] = control(session, ring, 70, "memory")

    run = run_ring(2, 50, 20, ids=[10, 70], on_ready=on_ready, timeout=120.0)
    assert len(run.rounds_s) == 50
    assert unwanted(reports["lcd"]["modules"]) == [], unwanted(reports["lcd"]["modules"])
