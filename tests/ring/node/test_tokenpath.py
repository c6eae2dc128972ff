"""The token path in C against the same path in Python (tokenring/node/tokenpath.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any

import pytest

from tests.support.processes import REPO
from tokenring._native import payload_call
from tokenring.node import tokenpath

SCENARIO = REPO / "tests" / "support" / "tokenpath_scenario.py"


def run_scenario(native: bool, *args: str) -> dict[str, Any]:
    env = dict(os.environ, TOKENRING_NATIVE="1" if native else "0")
    done = subprocess.run(
        [sys.executable, str(SCENARIO), *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_native_token_path_is_built_and_used():
    assert tokenpath.NATIVE, "tokenring/_tokenpath.c is not built: pip install -e . compiles it"
    from tokenring.node.node_os import NodeOS

    assert NodeOS._on_frame.__qualname__ == "TokenPath._on_frame"


def test_c_and_python_paths_send_the_same_bytes_and_keep_the_same_state():
    python, native = run_scenario(native=False), run_scenario(native=True)
    assert (python["native"], native["native"]) == (False, True)
    steps = {step["step"]: step for step in python["steps"]}
    # the scenario reaches every branch it names (checked on the reference, then compared)
    first = steps["a pass"]
    assert [entry[:2] for entry in first["sent"]] == [["frame", 30], ["message", 10]]
    assert steps["bad CRC"]["stats"]["rejected_crc"] == 1 and not steps["bad CRC"]["sent"]
    assert steps["an older epoch"]["sent"][0][2].startswith(b"S".hex())
    assert steps["the send fails"]["stats"]["send_errors"] == 1
    assert steps["the successor is gone: passes to main"]["sent"][0][:2] == ["frame", 10]
    assert steps["alone: passes to itself"]["sent"] == [steps["alone: passes to itself"]["sent"][0]]
    assert steps["alone: passes to itself"]["sent"][0][:2] == ["frame", 20]
    # a CRC-16 is no identity: a different pass that shares it is visited (it was taken for a
    # retry and dropped: a lost token about 20 times an hour on the robot's ring)
    before, twin = (
        steps["a pass before a CRC twin"],
        steps["the next round, other bytes, the same CRC: visited, not a retry"],
    )
    assert [entry[:2] for entry in twin["sent"]][:1] == [["frame", 30]]
    assert twin["stats"]["visits"] == before["stats"]["visits"] + 1
    assert twin["stats"]["duplicate_passes"] == before["stats"]["duplicate_passes"]
    assert python["calls"] == [10, 11]  # the hook ran while busy, not once idle
    # a pass over a new link arms the ack timer at once; a link's periodic confirmation asks
    # for an ack too but leaves the timer to the watchdog's next wake
    assert first["woke"] and first["state"]["_ack_pending"]
    periodic = steps["a periodic confirmation: asks, wakes nobody"]
    assert periodic["sent"][0][:2] == ["frame", 30] and periodic["state"]["_ack_pending"]
    assert not periodic["woke"]
    for reference, candidate in zip(python["steps"], native["steps"], strict=True):
        assert candidate == reference, f"the C path differs at step {reference['step']!r}"


@pytest.mark.parametrize("native", [True, False], ids=["C", "Python"])
def test_a_visit_that_may_wait_leaves_the_receiving_thread_and_the_frames_keep_their_order(native):
    result = run_scenario(native, "deferral")
    assert result["native"] is native
    assert result["returned_before_the_hook"]  # the receiving thread did not wait for the hook
    assert result["hook_ran_on_token_thread"]
    assert result["order"] == [1, 2, 3]
    assert result["inline_after"] and result["pending"] == 0


@pytest.mark.skipif(not tokenpath.NATIVE, reason="checks of the C type itself")
def test_the_c_type_refuses_a_visit_before_setup_and_a_wrong_buffer():
    path = tokenpath.TokenPathBase()
    with pytest.raises(RuntimeError, match="before the node set it up"):
        path._on_frame(bytes(514))
    path._frame_size = 514
    with pytest.raises(ValueError, match="_work must be 514 bytes"):
        path._work = bytearray(10)
    with pytest.raises(TypeError, match="_work must be bytearray"):
        path._work = bytes(514)
    with pytest.raises(TypeError):
        path._leaving = 1  # flags are bools, as the Python path keeps them


class _Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class _Sample:
    def __init__(self, data: bytes) -> None:
        self.payload = _Payload(data)


def test_the_tokens_subscriber_callback_hands_the_payload_bytes_on():
    got: list[bytes] = []
    callback = payload_call(got.append)
    if tokenpath.NATIVE:  # no Python frame per hop where the token path is in C
        assert type(callback).__name__ == "PayloadCall"
    callback(_Sample(b"\x01\x02"))
    callback(_Sample(bytes(514)))
    assert got == [b"\x01\x02", bytes(514)]

    def failing(frame: bytes) -> None:
        raise ValueError(f"{len(frame)} bytes")

    with pytest.raises(ValueError, match="3 bytes"):  # the handler's error reaches Zenoh's caller
        payload_call(failing)(_Sample(b"abc"))


@pytest.mark.skipif(not tokenpath.NATIVE, reason="checks of the C type itself")
def test_the_c_payload_call_refuses_what_is_not_a_sample_or_a_handler():
    from tokenring import _tokenpath  # type: ignore[attr-defined]

    with pytest.raises(TypeError, match="callable"):
        _tokenpath.PayloadCall(42)
    callback = _tokenpath.PayloadCall(print)
    with pytest.raises(TypeError, match="one sample"):
        callback()
    with pytest.raises(AttributeError):
        callback(object())


def test_the_visits_counters_read_and_write_as_plain_node_stats():
    from tokenring.node.node_os import NodeStats

    stats = NodeStats()
    assert stats.as_dict() == dict.fromkeys(NodeStats.FIELDS, 0)
    if tokenpath.NATIVE:  # C integers the visit adds to without touching a Python object
        assert type(stats.counters).__name__ == "Counters"
        # the C type's members and the Python list of them are one set
        assert {n for n in dir(stats.counters) if not n.startswith("_")} == set(tokenpath.HOT_COUNTERS)
    stats.visits += 3
    stats.frames_sent = 2**40
    stats.rounds_missed += 1
    assert (stats.visits, stats.frames_sent, stats.rounds_missed) == (3, 2**40, 1)
    assert stats.as_dict()["visits"] == 3 and stats.as_dict()["frames_sent"] == 2**40
