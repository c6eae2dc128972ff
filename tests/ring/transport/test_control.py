"""Control requests (tokenring/transport/control.py): one answer per request, and a fault that stops the
process takes effect only after its answer was handed over."""

from __future__ import annotations

import threading
from types import SimpleNamespace

import msgpack

from tokenring.node.faults import FaultInjector
from tokenring.transport.control import AfterReply, answer_query


class FakeQuery:
    """What answer_query reads of a Zenoh query, and a log of what it did."""

    def __init__(self, key: str, request: dict, events: list) -> None:
        self.key_expr = key
        self.payload = SimpleNamespace(to_bytes=lambda: msgpack.packb(request))
        self.events = events

    def reply(self, key: str, payload: bytes) -> None:
        self.events.append(("reply", msgpack.unpackb(payload)))


def test_an_action_after_the_reply_runs_after_it():
    events: list = []
    handlers = {"stop": lambda request: AfterReply({"stopping": True}, lambda: events.append(("action",)))}
    answer_query(FakeQuery("tokenring/r/ctl/10/stop", {}, events), handlers, "node 10")
    assert events == [("reply", {"ok": True, "result": {"stopping": True}}), ("action",)]


def test_a_crash_fault_answers_before_the_process_exits():
    events: list = []
    node = SimpleNamespace(
        name="motor", node_id=20, paused=False, rx_fault=None, tx_fault=None, msg_fault=None
    )
    exited = []
    faults = FaultInjector(node, exit_process=lambda code: exited.append(code))  # type: ignore[arg-type]
    query = FakeQuery("tokenring/r/ctl/20/fault", {"kind": "crash"}, events)
    answer_query(query, {"fault": faults.handle}, "node 20")
    assert events and events[0][0] == "reply" and events[0][1]["ok"], events
    assert exited == []  # the exit is scheduled after the answer, not before it
    for thread in threading.enumerate():
        if isinstance(thread, threading.Timer):
            thread.join(2.0)
    assert exited == [70]


def test_a_bad_request_gets_an_error_answer_and_no_action():
    events: list = []
    answer_query(
        FakeQuery("tokenring/r/ctl/20/fault", {"kind": "explode"}, events), {"fault": lambda r: 1 / 0}, "n"
    )
    assert events[0][1]["ok"] is False and "ZeroDivisionError" in events[0][1]["error"]
