"""One node as an OS process: a Zenoh session, the node OS, its control queryable, its program
(and an application's resident part of its OS, :mod:`tokenring.node.resident`).

Started by ``tokenring up`` (one per module) or by hand with ``tokenring node``. SIGINT and
SIGTERM make the node leave the ring cleanly and exit 0.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import logging
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgpack
import zenoh

from tokenring import extensions
from tokenring._util.process import StopEvent, wait_for_stop
from tokenring._util.process_memory import memory_report
from tokenring.contract import keys
from tokenring.contract.protocol import Protocol, load_protocol
from tokenring.contract.ring import parse_bitrate
from tokenring.errors import ProgramError, UsageError
from tokenring.node.channels import CommandMemory
from tokenring.node.faults import FaultInjector
from tokenring.node.node_os import NodeOS
from tokenring.node.pacing import install as install_profile
from tokenring.node.regeneration import RegenerationLedger
from tokenring.node.store import ProgramStore, check_store_root, default_store_root, file_stamp
from tokenring.node.system.layer import SystemLayer
from tokenring.node.system.vocabulary import DEFAULT_CAPACITY
from tokenring.transport.control import answer_query
from tokenring.transport.factory import make_transport
from tokenring.transport.zenoh_config import make_config, open_session

if TYPE_CHECKING:  # imported where used: main's PC link, an application's resident program
    from tokenring.node.pclink.server import PcLinkServer
    from tokenring.node.resident import ResidentHost

log = logging.getLogger("tokenring.nodeproc")

ControlHandler = Callable[[dict[str, Any]], Any]


#: a node's leave that takes longer reports its steps (the launcher kills after 1.5 s)
SLOW_LEAVE_S = 0.5


class NodeProcess:
    """The process around a :class:`NodeOS`: session, control plane, program, shutdown."""

    def __init__(
        self,
        protocol: Protocol,
        node_id: int,
        *,
        ring: str = keys.DEFAULT_RING,
        name: str | None = None,
        session: zenoh.Session,
        bitrate: float | None = 2.5e6,
        ack_mode: str = "adaptive",
        store: Path | None = None,
        capacity: int = DEFAULT_CAPACITY,
        transport: str = "zenoh",
        registry: str | None = None,
        link_session: zenoh.Session | None = None,
        profile: str | None = None,
        expected_nodes: int | None = None,
        resident: bool = True,
        stop_event: StopEvent | None = None,
    ) -> None:
        if name is not None:
            keys.check_node_name(name)  # it becomes a folder of the store: never '../..'
        self.protocol = protocol
        #: look for an application's resident program at boot (``--no-resident``: the launcher
        #: found none, and the node loads no application before a program needs its hardware)
        self.look_for_resident = resident
        self.ring = ring
        self.session = session
        # the token path's transport; the control plane below stays on the Zenoh session
        self.transport = make_transport(
            transport, session, ring, node_id, protocol.frame_size, registry, link_session=link_session
        )
        self.os = NodeOS(
            protocol,
            node_id,
            self.transport,
            name=name,
            bitrate=bitrate,
            ack_mode=ack_mode,
            expected_nodes=expected_nodes,
        )
        install_profile(self.os, profile, bitrate, self.os._now())
        #: set to end :meth:`wait` (the process's signal handlers set the same one)
        self.stop_event = stop_event if stop_event is not None else StopEvent()
        self.control: dict[str, ControlHandler] = {
            "stats": self._stats,
            "rounds": lambda _: self.os.round_times(),
            "visits": lambda _: self.os.stats.visits,
            "leave": self._request_leave,
            "program": self._program_report,
            "fault": lambda request: self.faults.handle(request),
            "peers": lambda _: self._peers(),
            "memory": lambda _: memory_report(),  # RSS, USS and what this process imported
        }
        self.faults = FaultInjector(self.os)
        # every regeneration counted by cause (spurious: no fault, no membership change); the
        # nodes tell each other when their faults change, so a regeneration caused by a fault
        # elsewhere (main lost the token, charger regenerates it) is not taken for a spurious one
        self.regenerations = RegenerationLedger(self.os, self.faults)
        self.regenerations.install()
        self.faults.on_change = self._tell_faults
        self.control["faultnote"] = self.regenerations.note
        if store is not None:  # what the inbox took survives a crash, like the stored program
            self.os.command_memory = CommandMemory(store / ring / self.os.name / "inbox-memory")
        # the OS's system commands; the node's program and time stamp live in its store
        self.system = SystemLayer(
            self.os,
            store=ProgramStore(store / ring / self.os.name if store else None, self.os.name),
            capacity=capacity,
            starter=self.start_program_class,
        )
        self.control["system"] = self.system.control
        self._queryable: Any = None
        self.hardware: Any = None
        self.pclink: PcLinkServer | None = None
        self.resident: ResidentHost | None = None

    def _stats(self, request: dict[str, Any] | None = None) -> dict[str, Any]:
        """The node's snapshot with its regenerations by cause and its uptime (``stats`` verb).
        ``{"with": ["faults", "system"]}`` adds its active faults and its system layer's report:
        a watcher asks each node one question where it would ask three, and every answer is
        the node's work between two token visits."""
        extra = (request or {}).get("with", [])
        if not isinstance(extra, list) or not all(
            isinstance(e, str) and e in keys.STATS_EXTRAS for e in extra
        ):
            raise UsageError(f"stats: 'with' takes a list of {', '.join(keys.STATS_EXTRAS)}, not {extra!r}")
        snapshot = self.os.snapshot()
        snapshot["regenerations"] = self.regenerations.report()
        snapshot["uptime_s"] = snapshot["regenerations"]["uptime_s"]
        if "faults" in extra:
            snapshot["faults"] = self.faults.listing()["faults"]
        if "system" in extra:
            snapshot["system"] = self.system.report()
        return snapshot

    def _tell_faults(self, listing: dict[str, Any]) -> None:
        """Tell every node of the ring that this node's faults changed (``ctl/*/faultnote``)."""
        payload = msgpack.packb({"id": self.os.node_id, "faults": sorted(listing["faults"])})
        try:
            self.session.get(
                keys.control(self.ring, "*", "faultnote"),
                lambda _reply: None,  # the answers say nothing; nobody waits for them
                target=zenoh.QueryTarget.ALL,
                consolidation=zenoh.ConsolidationMode.NONE,
                payload=payload,
                timeout=2.0,
            )
        except zenoh.ZError as exc:
            log.warning("could not tell the ring of a fault change: %s", exc)

    def _tell_launcher_program_failed(self, program: str, phase: str, error: str, wait: bool = False) -> None:
        """Tell the launcher that this node's program failed (``phase``: load, setup, run): its
        run ends with exit code 1. ``wait``: until it answered (the node is about to exit)."""
        request = {"id": self.os.node_id, "pid": os.getpid(), "program": program, "phase": phase}
        request["error"] = error
        options: dict[str, Any] = {"target": zenoh.QueryTarget.ALL, "payload": msgpack.packb(request)}
        key = keys.control(self.ring, "launcher", "programfailed")
        try:
            if wait:
                for _reply in self.session.get(key, timeout=2.0, **options):
                    pass
            else:  # nobody waits for the answer: a node started by hand has no launcher
                self.session.get(key, lambda _reply: None, timeout=2.0, **options)
        except zenoh.ZError as exc:
            log.warning("could not tell the launcher that the program failed: %s", exc)

    def _peers(self) -> dict[str, Any]:
        """The Zenoh links of this node (diagnostics: who it reaches directly)."""
        info = self.session.info
        return {
            "zid": str(info.zid()),
            "peers": [str(z) for z in info.peers_zid()],
            "routers": [str(z) for z in info.routers_zid()],
            "links": [f"{link.src} -> {link.dst}" for link in info.links()],
        }

    def _program_report(self, _: dict[str, Any]) -> dict[str, Any]:
        program = self.os.program
        return {
            "program": type(program).__name__ if program is not None else None,
            "error": self.os.program_error,
            "report": program.report() if program is not None else {},
        }

    def _request_leave(self, _: dict[str, Any]) -> dict[str, Any]:
        self.stop_event.set()
        return {"ok": True}

    def _on_query(self, query: zenoh.Query) -> None:
        answer_query(query, self.control, f"node {self.os.name}")

    def _request_ring_shutdown(self, reason: str) -> bool:
        """Ask the launcher to stop the whole ring cleanly; True if one answered."""
        replies = []
        try:
            for reply in self.session.get(
                keys.control(self.ring, "launcher", "shutdown"),
                payload=msgpack.packb({"reason": reason, "by": self.os.name}),
                target=zenoh.QueryTarget.ALL,  # a ring across hosts: every host's launcher
                timeout=2.0,
            ):
                if reply.ok is not None:
                    replies.append(reply)
        except zenoh.ZError as exc:
            log.error("ring shutdown request failed: %s", exc)
        if not replies:
            log.error("ring shutdown requested (%s) but no launcher answered", reason)
        return bool(replies)

    def start(self) -> None:
        self.os.request_ring_shutdown = self._request_ring_shutdown
        self.os.on_program_failed = self._tell_launcher_program_failed
        self.system.install()
        self.os.start()
        if self.os.node_id == self.os.preferred_master:  # main holds the PC's serial line
            from tokenring.node.pclink.server import PcLinkServer
            from tokenring.node.pclink.system_verbs import PcSystemVerbs

            self.pclink = PcLinkServer(self.os, self.session, self.ring)
            PcSystemVerbs(self.system).register(self.pclink)
            self.pclink.start()
        resident = extensions.resident_program(self.os.name) if self.look_for_resident else None
        if resident is not None:  # the application's part of this node's OS, from boot on
            if self.hardware is None:
                self.hardware = extensions.open_hardware(self.os.name, self.session, self.ring)
            from tokenring.node.resident import ResidentHost

            self.resident = ResidentHost(resident, self.os, self.system, self.hardware)
            self.control["resident"] = self.resident.control
            self.resident.start()
        # once it is in the ring (a joiner refused its ID must not answer for the node that holds
        # it) and whole: every verb it has answers from the first query on
        self._queryable = self.session.declare_queryable(
            keys.control(self.ring, self.os.node_id, "*"), self._on_query
        )

    def run_program(self, path: str | Path | None) -> None:
        if path is None:
            return
        from tokenring.node.program import load_program_file

        try:
            program_class, source = load_program_file(path)
        except ProgramError as exc:
            self._tell_launcher_program_failed(str(path), "load", str(exc), wait=True)
            raise
        wanted = getattr(program_class, "module", "")
        if wanted and wanted != self.os.name:
            raise UsageError(f"{path} is the program of {wanted!r}, not of node {self.os.name!r}")
        self.start_program_class(program_class)
        self.system.adopt(source, file_stamp(Path(path)), str(path), program_class)

    def start_program_class(self, program_class: type) -> None:
        """Start a user program with this module's hardware client (opened on first use)."""
        if self.hardware is None:
            self.hardware = extensions.open_hardware(self.os.name, self.session, self.ring)
        self.os.start_program(program_class, self.hardware)

    def wait(self, duration: float | None = None) -> None:
        """Run until a signal, a stop request or ``duration`` ends the node."""
        wait_for_stop(self.stop_event, duration)

    def shutdown(self) -> None:
        """Leave the ring; a leave slower than :data:`SLOW_LEAVE_S` says which step took the time."""
        steps: list[tuple[str, float]] = []
        clock = self.os._now
        started = last = clock()

        def step(name: str) -> None:
            nonlocal last
            now = clock()
            steps.append((name, now - last))
            last = now

        if self.resident is not None:
            self.resident.stop()
            step("resident")
        if self.pclink is not None:
            self.pclink.close()
            step("pc link")
        self.os.leave(grace=1.0)
        step("leave")
        self.system.close()
        if self._queryable is not None:
            with contextlib.suppress(zenoh.ZError):
                self._queryable.undeclare()
        step("system")
        if last - started > SLOW_LEAVE_S:
            spent = ", ".join(f"{name} {took * 1000:.0f} ms" for name, took in steps)
            stopping = "the ring was stopping" if self.os.ring_stopping else "the ring goes on"
            log.info("slow leave, %.2f s (%s): %s", last - started, stopping, spent)


def run_node(args: argparse.Namespace) -> int:
    """Entry of ``tokenring node``: run one node until SIGINT/SIGTERM or ``--duration``."""
    sys.setswitchinterval(0.0005)  # let the token handler in quickly beside a busy program
    protocol = load_protocol(args.protocol)
    if not 1 <= args.id <= 255:
        raise UsageError(f"--id {args.id} is outside 1..255")
    spec = protocol.by_id.get(args.id)
    if args.name and spec is not None and spec.name != args.name:
        raise UsageError(f"ID {args.id} is {spec.name!r} in protocol.yaml, not {args.name!r}")
    ring = keys.check_ring_name(args.ring)
    bitrate = parse_bitrate(args.bitrate)
    if args.capacity < 1:
        raise UsageError(f"--capacity {args.capacity}: a node must accept at least one byte")
    config = make_config(
        mode=args.mode,
        connect=args.connect or [],
        listen=args.listen or [],
        config_file=args.zenoh_config,
    )
    stop = StopEvent()

    def on_signal(signum: int, _frame: Any) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    if not args.no_store:
        check_store_root(Path(args.store) if args.store else default_store_root())
    if args.link_connect and not args.link_listen:
        raise UsageError("--link-connect needs --link-listen")
    if args.link_listen and args.transport != "zenoh":
        raise UsageError(f"--link-listen is a Zenoh link; --transport {args.transport} has its own")
    with contextlib.ExitStack() as sessions:
        session = sessions.enter_context(open_session(config))
        link_session = None
        if args.link_listen:
            link_config = make_config(
                listen=[args.link_listen],
                connect=[args.link_connect] if args.link_connect else [],
                gossip=False,
            )
            link_session = sessions.enter_context(open_session(link_config))
        node = NodeProcess(
            protocol,
            args.id,
            ring=ring,
            name=args.name,
            session=session,
            bitrate=bitrate,
            ack_mode=args.ack,
            store=None if args.no_store else Path(args.store) if args.store else default_store_root(),
            capacity=args.capacity,
            transport=args.transport,
            registry=args.registry,
            link_session=link_session,
            profile=args.profile,
            expected_nodes=args.expect,
            resident=not args.no_resident,
            stop_event=stop,
        )
        node.start()
        try:
            node.run_program(args.program)
            if args.autostart and not args.program:
                node.system.start_installed()
            # what booting allocated (modules, the protocol, Zenoh) lives as long as the node: out
            # of the collector's sight, a full collection no longer walks it during a visit
            gc.freeze()
            node.wait(args.duration)
        finally:
            node.shutdown()
    log.info("node %s left the ring", node.os.name)
    return 0
