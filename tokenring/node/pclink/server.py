"""The PC link: main's "serial line" through which PC-side tools talk to the ring.

In the seed the PC spoke to main over RS-232 and main relayed everything over the ring. Here
main's node process answers Zenoh queries on ``tokenring/<ring>/pc/<verb>`` (msgpack in and out)
and relays through its own node OS — so everything the tools do still goes through the token:

============  ===========================================================================
verb          request → result
============  ===========================================================================
``command``   ``{target, command, args, timeout, retry}`` → ``{transmitted, acknowledged,
              attempts}``: main sends a command into ``target``'s inbox (resending the same
              command, taken once, until acknowledged when ``retry``)
``read``      ``{channel}`` → ``{data, visits}``: main's copy of a data channel (main starts
              copying it on the first request)
``request``   ``{verb, payload}`` → whatever main's user program returns from
              ``on_pc_request(verb, payload)`` (explore start/stop, action files, ...)
``status``    ``{}`` → main's node snapshot
============  ===========================================================================

Later layers add verbs with :meth:`PcLinkServer.register` (system commands, downloads).
Only one request is served at a time, like a serial line.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import zenoh

from tokenring import runtime
from tokenring.contract import keys
from tokenring.errors import ChannelError, TransportError, UsageError
from tokenring.transport.control import answer_query

if TYPE_CHECKING:
    from tokenring.node.node_os import NodeOS


log = logging.getLogger("tokenring.pclink")


Handler = Callable[[dict[str, Any]], Any]


class PcLinkServer:
    """main's end of the serial line."""

    def __init__(self, os: NodeOS, session: zenoh.Session, ring: str) -> None:
        self.os = os
        self.session = session
        self.ring = ring
        self._rt = runtime.current()
        self._serial = self._rt.lock()
        self.handlers: dict[str, Handler] = {
            "command": self._command,
            "read": self._read,
            "request": self._request,
            "status": lambda _: self.os.snapshot(),
        }
        self._queryable: Any = None

    def register(self, verb: str, handler: Handler) -> None:
        """Add a verb (e.g. the system-command layer's ``scan`` or ``download``)."""
        self.handlers[verb] = handler

    def start(self) -> None:
        self._queryable = self.session.declare_queryable(keys.pc_link(self.ring, "*"), self._on_query)

    def close(self) -> None:
        if self._queryable is not None:
            with contextlib.suppress(zenoh.ZError):
                self._queryable.undeclare()
            self._queryable = None

    def _on_query(self, query: zenoh.Query) -> None:
        answer_query(query, self.handlers, "the PC link", lock=self._serial)

    def serve(self, verb: str, request: dict[str, Any]) -> Any:
        """Answer one request in this process, one at a time like the serial line (the PC side of
        a simulation, which has no Zenoh); raises what the verb raises."""
        handler = self.handlers.get(verb)
        if handler is None:
            raise UsageError(f"the PC link has no verb {verb!r} (has: {', '.join(sorted(self.handlers))})")
        with self._serial:
            return handler(request)

    # -- verbs ----------------------------------------------------------------------------------
    def _command(self, request: dict[str, Any]) -> dict[str, Any]:
        target = str(request.get("target", ""))
        name = request.get("command")
        args = dict(request.get("args") or {})
        timeout = float(request.get("timeout", 5.0))
        retry = bool(request.get("retry", True))
        if not target or name is None:
            raise UsageError("a PC link command needs a target and a command")
        try:
            channel = self.os.channel(target)
            channel.command(name)  # type: ignore[attr-defined]
        except (ChannelError, AttributeError) as exc:
            raise UsageError(str(exc)) from None
        return asdict(self.os.send_until_acknowledged(target, name, args, timeout, retry))

    def _read(self, request: dict[str, Any]) -> dict[str, Any]:
        name = str(request.get("channel", ""))
        try:
            buffer = self.os.subscribe(name, owner="os")
        except ChannelError as exc:
            raise UsageError(str(exc)) from None
        if buffer.visits == 0:
            deadline = self._rt.monotonic() + float(request.get("timeout", 2.0))
            while buffer.visits == 0 and self._rt.monotonic() < deadline:
                self.os.wait_visit(0.1)
            if buffer.visits == 0:
                raise TransportError(f"no token visit reached main within the timeout to copy {name}")
        return {"data": buffer.read(), "visits": buffer.visits}

    def _request(self, request: dict[str, Any]) -> Any:
        program = self.os.program
        handler = getattr(program, "on_pc_request", None)
        if handler is None:
            raise UsageError(
                f"main's program ({type(program).__name__ if program else 'none'}) takes no PC requests"
            )
        if not self.os.program_set_up:  # its handler would meet half-built state
            raise UsageError(f"main's program ({type(program).__name__}) is still setting up; ask again")
        return handler(str(request.get("verb", "")), request.get("payload") or {})
