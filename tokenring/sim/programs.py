"""User programs in virtual time: each node's program started on its simulated node, and main's
PC link answered in the same process (issue 55).

The programs are the very files ``tokenring up`` downloads into the node processes
(``<dir>/<node name>.py``), started as ``up --no-download`` starts them, each with the hardware
its application gives it; every wait of theirs is the runtime's. :class:`LocalPcLink` is the PC
side of main's serial line: the same verbs as :class:`~tokenring.host.PcLink` (``command``,
``read``, ``request``, ``status``), served by main's own :class:`PcLinkServer` without Zenoh.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgpack

from tokenring.errors import TokenRingError, UsageError
from tokenring.node.pclink.server import PcLinkServer
from tokenring.node.program import load_program_file
from tokenring.transport.control import _jsonable

if TYPE_CHECKING:
    from tokenring.node.node_os import NodeOS
    from tokenring.sim.ring import SimRing

log = logging.getLogger("tokenring.sim")


def start_programs(ring: SimRing, programs: Path, hardware: Callable[[str], Any]) -> list[str]:
    """Start ``programs/<name>.py`` on each node of ``ring`` that has one, in node order, with
    ``hardware(name)`` as its ``self.hw``; returns the names of the nodes that run one."""
    started = []
    for node_id in sorted(ring.nodes):
        node = ring.nodes[node_id]
        path = programs / f"{node.name}.py"
        if not path.is_file():
            continue
        program_class, _source = load_program_file(path)
        wanted = getattr(program_class, "module", "")
        if wanted and wanted != node.name:
            raise UsageError(f"{path} is the program of {wanted!r}, not of node {node.name!r}")
        node.start_program(program_class, hardware(node.name))
        started.append(node.name)
    return started


def program_errors(ring: SimRing) -> dict[str, str]:
    """The nodes whose program failed (raised in setup or run), with the error's last line."""
    return {node.name: node.program_error for node in ring.nodes.values() if node.program_error}


class LocalPcLink:
    """main's PC link inside the simulation: what a PC tool sends over Zenoh, served directly by
    main's :class:`PcLinkServer` (answers pass through msgpack, as on the wire)."""

    def __init__(self, main: NodeOS, timeout: float = 5.0) -> None:
        self.server = PcLinkServer(main, None, "sim")  # type: ignore[arg-type]  # no session: never started
        self.timeout = timeout

    def call(self, verb: str, request: dict[str, Any] | None = None, timeout: float | None = None) -> Any:
        """One request/answer; main's errors become :class:`UsageError` as :class:`PcLink`'s do."""
        try:
            answer = self.server.serve(verb, request or {})
        except TokenRingError as exc:
            raise UsageError(str(exc)) from None
        except Exception as exc:  # as the Zenoh server answers a verb's bug: an error, not a crash
            log.exception("the PC link: verb %s failed", verb)
            raise UsageError(f"{type(exc).__name__}: {exc}") from None
        return msgpack.unpackb(msgpack.packb(answer, default=_jsonable))

    def command(
        self, target: str, name: str, timeout: float = 5.0, retry: bool = True, **args: Any
    ) -> dict[str, Any]:
        """Have main send a command into ``target``'s inbox; returns transmitted/acknowledged."""
        request = {"target": target, "command": name, "args": args, "timeout": timeout, "retry": retry}
        answer: dict[str, Any] = self.call("command", request, timeout)
        return answer

    def read(self, channel: str, timeout: float = 2.0) -> dict[str, Any]:
        """main's latest copy of a data channel, decoded with protocol.yaml."""
        data: dict[str, Any] = self.call("read", {"channel": channel, "timeout": timeout}, timeout)["data"]
        return data

    def request(self, verb: str, timeout: float | None = None, **payload: Any) -> Any:
        """A request to main's user program (``on_pc_request``)."""
        return self.call("request", {"verb": verb, "payload": payload}, timeout)

    def status(self) -> dict[str, Any]:
        answer: dict[str, Any] = self.call("status")
        return answer
