"""The tool side of fault injection: requests to a running ring's nodes (``fault``, ``chaos``, the web view)."""

from __future__ import annotations

import time
from typing import Any

from tokenring.contract import keys
from tokenring.contract.faults import IDEMPOTENT
from tokenring.errors import TokenRingError, UsageError
from tokenring.transport.session import query, query_one


class FaultClient:
    """The tool side: sends fault requests to nodes of a running ring (``fault``, ``chaos``)."""

    def __init__(self, session: Any, ring: str, timeout: float = 2.0) -> None:
        self.session = session
        self.ring = ring
        self.timeout = timeout

    def inject(self, node_id: int, request: dict[str, Any]) -> dict[str, Any]:
        """Apply a validated request on one node; a real ``resume`` goes through the launcher."""
        if request["kind"] == "resume" and not request.get("soft"):
            return self.resume(node_id)
        key = keys.control(self.ring, node_id, "fault")
        try:
            return query_one(self.session, key, request, timeout=self.timeout)
        except TokenRingError:
            if request["kind"] not in IDEMPOTENT:
                raise
            # its answer may have been lost on a busy machine: asking twice does no harm
            return query_one(self.session, key, request, timeout=self.timeout)

    def resume(self, node_id: int) -> dict[str, Any]:
        """End a hang: SIGCONT through the launcher (a stopped node answers nothing), then clear."""
        deadline = time.monotonic() + self.timeout + 2.0
        refused = ""  # what a launcher said instead of sending it
        while time.monotonic() < deadline:
            # SIGCONT every time round: a hang asked for just before stops its node only after
            # answering (AFTER_REPLY_S), so one SIGCONT can come before the stop it should end
            launcher = query(
                self.session,
                keys.control(self.ring, "launcher", "signal"),
                {"id": node_id, "signal": "CONT"},
                max(0.1, min(self.timeout, deadline - time.monotonic())),
                enough=lambda answers: any(a.get("ok") for _, a in answers),
                everyone=True,
            )
            answer = query(
                self.session, keys.control(self.ring, node_id, "fault"), {"kind": "resume"}, timeout=1.0
            )
            if answer and answer[0][1].get("ok"):
                return answer[0][1]["result"]
            # a ring across hosts has a launcher per host: only the node's own sends SIGCONT
            if launcher and not any(answer.get("ok") for _, answer in launcher):
                refused = f" (the launcher: {launcher[0][1].get('error', 'refused')})"
                break
            time.sleep(0.05)  # no answer from either yet: a busy host, ask again until the deadline
        raise UsageError(
            f"node {node_id} does not answer and no launcher of ring {self.ring!r} could send it SIGCONT{refused}; "
            "send SIGCONT to its process yourself (its pid is in 'tokenring status --json')"
        )
