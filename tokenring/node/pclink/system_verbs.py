"""The PC link's system verbs on main (``scan``, ``download``, ``job``, ``start``, ``stop``,
``errors``): what ``tokenring load`` calls, carried out as system commands on the ring."""

from __future__ import annotations

import itertools
import logging
from typing import TYPE_CHECKING, Any

from tokenring.errors import UsageError

if TYPE_CHECKING:
    from tokenring.node.pclink.server import PcLinkServer

from tokenring.node.program import program_sha256
from tokenring.node.store import now_ms
from tokenring.node.system.layer import SystemLayer
from tokenring.node.system.vocabulary import SystemCommandError, Transaction

log = logging.getLogger("tokenring.system")


class PcSystemVerbs:
    """The system commands on main's serial line: ``scan``, ``download``, ``job``, ``start``,
    ``stop``, ``errors`` (see :mod:`tokenring.node.pclink.server`). Downloads run as jobs the PC polls, so
    the serial line stays free for progress requests."""

    def __init__(self, layer: SystemLayer) -> None:
        self.layer = layer
        self.jobs: dict[int, Transaction] = {}
        self._ids = itertools.count(1)

    def register(self, server: PcLinkServer) -> None:
        for verb in ("scan", "download", "job", "start", "stop", "errors"):
            server.register(verb, getattr(self, verb))

    def _node(self, value: Any) -> int:
        if isinstance(value, int) and 1 <= value <= 255:
            return value
        try:
            return self.layer.os.protocol.node(str(value)).id
        except Exception as exc:
            raise UsageError(str(exc)) from None

    def _live(self, node_id: int) -> None:
        if node_id not in self.layer.os.membership.live:
            raise UsageError(f"node {node_id} is not on the ring")

    def scan(self, request: dict[str, Any]) -> dict[str, Any]:
        """ARCNET_SCAN, then ARCNET_GET_CONFIG of every node found."""
        layer = self.layer
        clock = layer._rt.monotonic
        t0 = clock()
        ids = layer.scan(float(request.get("timeout", 5.0)))
        configs = layer.configs(ids) if ids else {}
        return {"nodes": [configs[i] for i in ids if i in configs], "seconds": clock() - t0}

    def download(self, request: dict[str, Any]) -> dict[str, Any]:
        """``{target, source, stamp_ms, compress, start}`` → ``{job, chunks, bytes}``."""
        target = self._node(request.get("target"))
        self._live(target)
        source = request.get("source")
        if not isinstance(source, bytes):
            raise UsageError("download needs the program's source as bytes")
        stamp = int(request.get("stamp_ms") or now_ms())
        if request.get("restamp"):  # the node has this very program: only the new time stamp
            steps = [self.layer.restamp_step(target, program_sha256(source), stamp)]
        else:
            steps = self.layer.download_steps(
                target,
                source,
                stamp,
                compress=bool(request.get("compress", True)),
                start=bool(request.get("start", False)),
            )
        tx = self.layer.submit(steps, f"download to {target}")
        job = next(self._ids)
        self.jobs[job] = tx
        for old in [j for j in self.jobs if j < job - 50]:
            del self.jobs[old]
        chunks = sum(1 for s in steps if s.code == self.layer.DATA)
        return {
            "job": job,
            "chunks": chunks,
            "bytes": sum(len(s.payload) - 2 for s in steps if s.code == self.layer.DATA),
        }

    def job(self, request: dict[str, Any]) -> dict[str, Any]:
        tx = self.jobs.get(int(request.get("job", 0)))
        if tx is None:
            raise UsageError(f"no download job {request.get('job')!r}")
        if request.get("cancel") and not tx.done.is_set():
            tx.cancelled = True
        progress = tx.progress()
        if tx.failed_step is not None and tx.failed_step < len(tx.steps):
            code = tx.steps[tx.failed_step].code
            progress["failed_command"] = self.layer.os.protocol.system_command_name(code)
        return progress

    def start(self, request: dict[str, Any]) -> dict[str, Any]:
        """The whole system (ARCNET_START_SYSTEM) or one node's program (ARCNET_START_PROGRAM)."""
        return self._start_stop(request, start=True)

    def stop(self, request: dict[str, Any]) -> dict[str, Any]:
        return self._start_stop(request, start=False)

    def _start_stop(self, request: dict[str, Any], start: bool) -> dict[str, Any]:
        layer = self.layer
        timeout = float(request.get("timeout", 10.0))
        target = request.get("target")
        if target in (None, "", "all"):
            code, what = (layer.START_SYSTEM, "start system") if start else (layer.STOP_SYSTEM, "stop system")
            return {"nodes": layer.broadcast(code, what, timeout)}
        node = self._node(target)
        self._live(node)
        step = layer.start_step(node) if start else layer.stop_step(node)
        try:
            layer.execute([step], ("start" if start else "stop") + f" program of {node}", timeout)
        except SystemCommandError as exc:
            return {"nodes": [], "error": str(exc)}
        return {"nodes": [node]}

    def errors(self, request: dict[str, Any]) -> dict[str, Any]:
        since = int(request.get("since", 0))
        return {"errors": [e for e in self.layer.errors if e["n"] > since]}
