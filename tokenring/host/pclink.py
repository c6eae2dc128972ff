"""The PC side of main's serial line (:mod:`tokenring.node.pclink.server`): what ``drive``,
``explore`` and ``load`` talk through."""

from __future__ import annotations

import time
from typing import Any

import msgpack
import zenoh

from tokenring.contract import keys
from tokenring.errors import TransportError, UsageError
from tokenring.transport.zenoh_config import unanswered_hint


class PcLink:
    """The PC side of the serial line: what ``tokenring drive``, ``explore``, ``load`` use."""

    def __init__(
        self,
        session: zenoh.Session,
        ring: str = keys.DEFAULT_RING,
        timeout: float = 5.0,
        connect_timeout: float = 5.0,
    ) -> None:
        self.session = session
        self.ring = keys.check_ring_name(ring)
        self.timeout = timeout
        self.connect_timeout = connect_timeout
        self._connected = False

    def call(self, verb: str, request: dict[str, Any] | None = None, timeout: float | None = None) -> Any:
        """One request/answer on the serial line; errors from main become :class:`UsageError`.

        A fresh session reaches main only once gossip has connected the two, so a first call
        that nobody answers is repeated for up to ``connect_timeout`` seconds."""
        wait = (timeout if timeout is not None else self.timeout) + 2.0
        deadline = time.monotonic() + self.connect_timeout
        while True:
            try:
                replies = list(
                    self.session.get(
                        keys.pc_link(self.ring, verb), payload=msgpack.packb(request or {}), timeout=wait
                    )
                )
            except zenoh.ZError as exc:
                raise TransportError(f"PC link {verb}: {exc}") from exc
            answers = [r.ok for r in replies if r.ok is not None]
            if answers or self._connected or time.monotonic() >= deadline:
                break
            time.sleep(0.1)
        if not answers:
            raise TransportError(
                f"main did not answer on the PC link of ring {self.ring!r} (is the ring up{unanswered_hint()}?)"
            )
        self._connected = True
        reply = msgpack.unpackb(answers[0].payload.to_bytes())
        if not reply.get("ok"):
            raise UsageError(reply.get("error", f"PC link {verb} failed"))
        return reply.get("result")

    def command(
        self, target: str, name: str, timeout: float = 5.0, retry: bool = True, **args: Any
    ) -> dict[str, Any]:
        """Have main send a command into ``target``'s inbox; returns transmitted/acknowledged."""
        request = {"target": target, "command": name, "args": args, "timeout": timeout, "retry": retry}
        return self.call("command", request, timeout)

    def read(self, channel: str, timeout: float = 2.0) -> dict[str, Any]:
        """main's latest copy of a data channel, decoded with protocol.yaml."""
        return self.call("read", {"channel": channel, "timeout": timeout}, timeout)["data"]

    def request(self, verb: str, timeout: float | None = None, **payload: Any) -> Any:
        """A request to main's user program (``on_pc_request``)."""
        return self.call("request", {"verb": verb, "payload": payload}, timeout)

    def status(self) -> dict[str, Any]:
        return self.call("status")


def open_link(session: zenoh.Session, ring: str, wait: float = 3.0) -> PcLink:
    """A PC link to main, once main answers (a fresh session needs a moment to find it)."""
    link = PcLink(session, ring)
    deadline = time.monotonic() + wait
    while True:
        try:
            link.call("status", timeout=1.0)
            return link
        except TransportError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
