"""``tokenring up``: every node as its own OS process on one Zenoh network, supervised.

The launcher holds the ring's tap endpoint (``tcp/127.0.0.1:7447`` unless ``--listen`` says
otherwise; if that port is taken by another ring it joins that network instead — rings are
namespaces — but it refuses a ring another launcher holds there, naming it, and always node IDs
that are live there), starts one ``tokenring node`` process per node with its log lines prefixed by the
node's name, reports any node that dies with its exit code, and on Ctrl-C, SIGTERM or the end
of ``--duration`` stops every process it started within 2 s. Children also carry
``PR_SET_PDEATHSIG``, and a keeper process holds their process groups, so that even a killed
launcher leaves no orphans — nor anything a node's program started.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import zenoh

from tokenring._util.process import die_with_parent
from tokenring.contract import keys
from tokenring.contract.faults import CRASH_EXIT_CODE
from tokenring.contract.ring import EVENT_RING_STOPPING, RING_EVENT
from tokenring.errors import UsageError
from tokenring.host.children import (
    KILL_REAP_S,
    RESPAWN_DELAY_S,
    STOP_TIMEOUT_S,
    ExitWatch,
    GroupEnder,
    PrefixedOutput,
    describe_exit,
)
from tokenring.host.network import open_launcher_session
from tokenring.host.node_commands import NodeCommandLines
from tokenring.host.ring_claim import refuse_a_ring_in_use
from tokenring.host.services import ServiceChild, ServicePlan, ServiceSupervisor
from tokenring.host.stall import StallWatch
from tokenring.transport.control import answer_query
from tokenring.transport.zenoh import RingViewServer, peer_to_peer
from tokenring.transport.zenoh_config import node_environment

if TYPE_CHECKING:
    from tokenring.host.remote import HostShares, Share

#: a ring bigger than this boots in waves of at most this many nodes at a time (8 per core)
BOOT_CONCURRENCY = 8 * max(1, os.cpu_count() or 1)
#: how often the supervisor checks its children when their pidfds wake it (a safety net), and
#: when they cannot (no pidfd_open)
EXIT_CHECK_S = 1.0
CHILD_POLL_S = 0.05
#: what a child started gets this long after SIGTERM (once the child exited) before SIGKILL
GROUP_GRACE_S = 1.0


def process_stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped (SIGSTOP: a hang fault), from ``/proc``."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as stat:
            return stat.read().rsplit(b")", 1)[1].split()[0] in (b"T", b"t")
    except (OSError, IndexError):
        return False


@dataclass
class NodePlan:
    """One node the launcher runs."""

    node_id: int
    name: str
    program: str | None = None
    extra_args: list[str] = field(default_factory=list)


@dataclass
class Child:
    plan: NodePlan
    process: subprocess.Popen
    started: float
    restarts: int = 0
    reported: bool = False
    group_ended: bool = False  # what is left of its process group was told to end


class Launcher(NodeCommandLines):
    """Starts, watches and stops the node processes of one ring."""

    def __init__(
        self,
        plans: Sequence[NodePlan],
        *,
        ring: str = keys.DEFAULT_RING,
        bitrate: str = "2.5M",
        ack_mode: str = "adaptive",
        connect: Sequence[str] = (),
        listen: Sequence[str] = (),
        zenoh_config: str | None = None,
        protocol_path: str | None = None,
        log_level: str = "info",
        respawn: bool = False,
        output: IO[str] | None = None,
        extra_node_args: Sequence[str] = (),
        services: Sequence[ServicePlan] = (),
        router: bool = False,
        links: bool = False,
        transport: str = "zenoh",
        profile: str | None = None,
        boot_concurrency: int = BOOT_CONCURRENCY,
        env: Mapping[str, str] | None = None,
        residents: bool = True,
    ) -> None:
        if boot_concurrency < 1:
            raise UsageError(f"--boot-wave {boot_concurrency}: at least one node must boot at a time")
        self.plans = list(plans)
        self.boot_concurrency = boot_concurrency
        self.extra_env = dict(env or {})  # added to every node's environment (chaos: the ledger)
        #: False: no node loads an application's resident program (a bare ring: the benchmark's)
        self.residents = residents
        if transport != "zenoh":
            from tokenring.transport.factory import require_backend

            require_backend(transport)  # before any node starts
        self.transport = transport  # udp/zmq: the token path over sockets, membership from our registry
        self.profile = profile  # tokenring.node.pacing: emulated hardware timing on every node
        self.registry: Any = None
        self.router = router  # this launcher is its host's Zenoh router; its nodes are clients
        if links and not router:
            raise UsageError("direct links to the ring successor need the launcher as the nodes' router")
        if links and transport != "zenoh":
            raise UsageError(f"direct links are Zenoh links; --transport {transport} has its own")
        if links and (zenoh_config or os.environ.get("ZENOH_CONFIG")):
            # the links are plain TCP on loopback, outside the config's (a secured ring's) rules
            raise UsageError("direct links (--links) are plain TCP: not on a ring with a Zenoh config file")
        #: the token's hop also on a direct link from each node to its successor (a second
        #: session per node, see :mod:`tokenring.transport.links`); their ports, by node ID
        self.links = links
        self.link_ports: dict[int, int] = {}
        self.services = list(services)
        self.service_supervisor = ServiceSupervisor(self)
        #: the other hosts' shares of a ring across hosts (``up --hosts``), supervised like nodes
        self.hosts: HostShares | None = None
        #: before each node's name in the output: its host's, on a ring across hosts
        self.label_prefix = ""
        #: the whole ring's size when this launcher runs a share of it (the nodes' ``--expect``)
        self.expected_nodes: int | None = None
        #: tell the ring it is stopping as a whole when this launcher stops (not a host's share:
        #: the rest of the ring goes on, and its nodes must still hand the token over)
        self.announce_stop = True
        #: why this run is not whole, one line each (a service died, a program failed): exit 1
        self.failures: list[str] = []
        # what each child started ends with it: its process group is ended once it exits
        self._groups = GroupEnder(GROUP_GRACE_S)
        self._keeper_reported = False
        self.ring = keys.check_ring_name(ring)
        self.bitrate = bitrate
        self.ack_mode = ack_mode
        self.connect = list(connect)
        self.listen = list(listen)
        self.zenoh_config = zenoh_config
        self.protocol_path = protocol_path
        self._protocol_cache: Any = None
        self.log_level = log_level
        self.respawn = respawn
        self.extra_node_args = list(extra_node_args)
        self.session: zenoh.Session | None = None
        self.endpoint: str | None = None
        self.joined_existing = False
        self.children: dict[int, Child] = {}
        self.deaths: list[tuple[str, int, int | None]] = []
        self._stop = threading.Event()
        self._children_lock = threading.RLock()
        self._supervisor: threading.Thread | None = None
        self._booter: threading.Thread | None = None
        self._children_gone = threading.Event()
        self._supervision_ended = threading.Event()  # the supervisor touches no child any more
        # children's exits wake the supervisor through their pidfds (readable once a process
        # exits); polling 255 children 20 times a second took CPU from the router in this process
        self._exits = ExitWatch()
        self._respawn_due: dict[int, float] = {}  # node ID -> when --respawn starts it again
        self._stop_signal: int | None = None
        self._queryable: Any = None
        self._view_server: RingViewServer | None = None
        self._stall_watch: StallWatch | None = None  # says when the launcher itself stood still
        self.shutdown_reason: str | None = None
        #: this launcher among others on the network (its own status answers its own question)
        self.instance = os.urandom(8).hex()
        self.started_at = time.time()
        self.booting = False  # programs are being downloaded over the ring (``up``)
        width = max(
            (len(name) for name in [*(p.name for p in self.plans), *(s.name for s in self.services)]),
            default=4,
        )
        self.output = PrefixedOutput(output or sys.stdout, width)

    # -- output ---------------------------------------------------------------------------------
    def say(self, text: str, name: str = "up") -> None:
        """One prefixed line of output (never blocks: see :class:`PrefixedOutput`)."""
        self.output.say(text, name)

    def divert_output(self, output: IO[str]) -> IO[str]:
        """Send the prefixed lines to ``output`` from now on (an interactive program took the
        terminal); returns where they went before, to divert them back."""
        return self.output.divert(output)

    def flush_output(self, timeout: float = 1.0) -> None:
        """Wait until the queued lines are written (for a clean end of the run)."""
        self.output.flush(timeout)

    @property
    def stopping(self) -> bool:
        """A stop was requested (or is under way)."""
        return self._stop.is_set()

    # -- session --------------------------------------------------------------------------------
    def _open_session(self) -> None:
        opened = open_launcher_session(
            router=self.router,
            listen=self.listen,
            connect=self.connect,
            zenoh_config=self.zenoh_config,
            ring=self.ring,
        )
        self.session, self.endpoint, self.joined_existing = (
            opened.session,
            opened.endpoint,
            opened.joined_existing,
        )
        if opened.note:
            self.say(opened.note)

    # -- children -------------------------------------------------------------------------------
    def popen_child(
        self, argv: list[str], name: str, *, stdin: int = subprocess.DEVNULL, watch: bool = True
    ) -> subprocess.Popen:
        """Start a child (a node, a service, another host's share) in a process group of its own,
        its output prefixed with ``name`` (unless not ``watch``: the caller watches it), ended
        with the launcher however that ends."""
        env = node_environment()
        env.update(self.extra_env)
        process = subprocess.Popen(
            argv,
            stdin=stdin,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
            env=env,
            preexec_fn=die_with_parent,  # only prctl in the child: async-signal-safe
            # a group of its own, ended once the child exits (GroupEnder): what a node's program
            # started ends with the node, even when the node was killed
            process_group=0,
        )
        self._groups.adopt(process.pid)
        if self._groups.keeper.failed and not self._keeper_reported:
            self._keeper_reported = True
            self.say(self._groups.keeper.failed)
        assert process.stdout is not None
        if watch:
            self.output.watch(process.stdout, name)
        return process

    @property
    def service_children(self) -> dict[str, subprocess.Popen]:
        """The running process of each service, by name."""
        return self.service_supervisor.children

    def watch_exit(self, pid: int, record: Child | ServiceChild | Share) -> None:
        """Wake the supervisor when child ``pid`` exits."""
        self._exits.add(pid, record)

    def child_list(self) -> list[Child]:
        """The node processes started so far (a big ring is still adding them while it boots)."""
        with self._children_lock:
            return list(self.children.values())

    def spawn(self, plan: NodePlan) -> Child:
        previous = self.children.get(plan.node_id)
        command = self.command_for(plan)
        if previous is not None and not plan.program:
            command.append("--autostart")  # a respawned bare node runs the program in its store
        child = Child(plan, self.popen_child(command, self.label_prefix + plan.name), time.monotonic())
        if previous is not None:
            child.restarts = previous.restarts + 1
        self.children[plan.node_id] = child
        self._exits.add(child.process.pid, child)
        return child

    def start(self) -> None:
        """Open the tap session and start every node; if that fails, stop what did start (the
        session's callback threads would otherwise keep the process alive after the error)."""
        try:
            self._start()
        except BaseException:
            self.stop()
            raise

    def _start(self) -> None:
        self._open_session()
        assert self.session is not None
        verbs = LauncherVerbs(self)
        self.started_at = time.time()  # before its status answers: the older of two launchers wins
        self._queryable = self.session.declare_queryable(
            keys.control(self.ring, "launcher", "*"),
            lambda query: answer_query(query, verbs.handlers, "the launcher"),
        )
        refuse_a_ring_in_use(
            self.session,
            self.ring,
            instance=self.instance,
            started_at=self.started_at,
            node_ids=[p.node_id for p in self.plans],
            joining=bool(self.connect),
            zenoh_membership=self.transport == "zenoh",
        )
        if self.transport == "zenoh" and peer_to_peer(self.session):
            self._view_server = RingViewServer(self.session, self.ring)
        self._stall_watch = StallWatch(self.session, self.ring, self.say, router=self.router).start()
        where = self.endpoint or ", ".join(self.node_connect())
        self.say(
            f"ring {self.ring!r}: starting {len(self.plans)} nodes "
            f"({', '.join(f'{p.name}={p.node_id}' for p in self.plans)}) on {where}, "
            f"bitrate {self.bitrate}" + (f", profile {self.profile}" if self.profile else "")
        )
        self.output.start_reading(self._stop)
        for service in self.services:
            self.service_supervisor.start(service)
        if self.hosts is not None:
            self.hosts.start()  # the other hosts' shares boot while this host's nodes do
        if self.transport != "zenoh":
            from tokenring.transport.registry import MembershipRegistry

            self.registry = MembershipRegistry().start()
        if self.transport == "zenoh" and len(self.plans) > self.boot_concurrency:
            self.say(f"booting in waves: at most {self.boot_concurrency} nodes starting at a time")
            self._booter = threading.Thread(target=self._boot_in_waves, name="launcher-boot", daemon=True)
            self._booter.start()
        else:
            for plan in self.plans:
                self.spawn(plan)
        # supervision (death reports, --respawn) runs beside whoever owns the launcher: `up`'s
        # run() loop as well as in-process users such as chaos and the benchmarks
        self._supervisor = threading.Thread(target=self._supervise, name="launcher-supervisor", daemon=True)
        self._supervisor.start()

    def _boot_in_waves(self) -> None:
        """Start a big ring's nodes so that at most ``boot_concurrency`` are booting (started,
        not yet live) at a time: 255 interpreters importing at once on two cores starve each
        other and the router, whose handshakes then time out (nodes exit unable to connect)."""
        assert self.session is not None
        live: set[int] = set()
        changed = threading.Condition()

        def on_liveliness(sample: zenoh.Sample) -> None:
            node_id = keys.id_from_key(str(sample.key_expr))
            if node_id is not None and sample.kind == zenoh.SampleKind.PUT:
                with changed:
                    live.add(node_id)
                    changed.notify()

        subscriber = self.session.liveliness().declare_subscriber(keys.node(self.ring, "*"), on_liveliness)
        try:
            for plan in self.plans:
                with changed:
                    while not self._stop.is_set():
                        booting = [
                            c
                            for c in self.child_list()
                            if c.plan.node_id not in live and c.process.poll() is None
                        ]
                        if len(booting) < self.boot_concurrency:
                            break
                        changed.wait(0.2)
                with self._children_lock:  # stop() lists the children under this lock
                    if self._stop.is_set():
                        break
                    self.spawn(plan)
        finally:
            with contextlib.suppress(zenoh.ZError):
                subscriber.undeclare()
        # the nodes' parent-death signal fires when the *thread* that started them ends: this
        # one must outlive them, so it waits until stop() has seen them all exit
        self._children_gone.wait()

    def _supervise(self) -> None:
        """Report exits and respawn until the stop; then outlive the nodes this thread respawned
        (their parent-death signal fires when the *thread* that started them ends: a respawned
        node was SIGKILLed at every stop instead of leaving the ring)."""
        try:
            while not self._stop.is_set():
                timeout = EXIT_CHECK_S if self._exits.works else CHILD_POLL_S
                due = [*self._respawn_due.values(), *self.service_supervisor.due()]
                if self.hosts is not None:
                    due += self.hosts.due()
                if due:
                    timeout = max(0.0, min(timeout, min(due) - time.monotonic()))
                exited = self._exits.wait(timeout)
                if self._stop.is_set():
                    break
                for child in exited:
                    # reap it here: Popen.poll() answers None while another thread is inside
                    # poll() (status queries, run()), and the exit would wait for the next check
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        child.process.wait(timeout=1.0)
                with self._children_lock:
                    self.check_children()
        finally:
            self._exits.close_reading()
            self._supervision_ended.set()
        self._children_gone.wait()

    def check_children(self) -> None:
        """Report nodes and services that died and end what they started; with ``--respawn``
        start them again RESPAWN_DELAY_S later (a service only if that is safe)."""
        for child in self.child_list():
            code = child.process.poll()
            if code is None or child.reported:
                continue
            child.reported = True
            self.end_group(child)
            plan = child.plan
            self.deaths.append((plan.name, plan.node_id, code))
            self.say(f"node {plan.name} (id {plan.node_id}) {describe_exit(code)}")
            if self.respawn and not self._stop.is_set():
                self._respawn_due.setdefault(plan.node_id, time.monotonic() + RESPAWN_DELAY_S)
        self.service_supervisor.check(stopping=self._stop.is_set())
        if self.hosts is not None:
            self.hosts.check(stopping=self._stop.is_set())
        now = time.monotonic()
        for node_id, due in list(self._respawn_due.items()):
            if now >= due and not self._stop.is_set():
                del self._respawn_due[node_id]
                plan = self.children[node_id].plan
                self.say(f"respawning {plan.name} (id {plan.node_id})")
                self.spawn(plan)

    def signal_groups(self, signum: int, pgids: Sequence[int] | None = None) -> list[int]:
        """Send ``signum`` to the process group of every running node and service (or to
        ``pgids``), skipping a node a fault holds stopped; returns the groups signalled."""
        if pgids is None:
            leaders = [c.process for c in self.child_list()] + list(self.service_children.values())
            pgids = [p.pid for p in leaders if p.poll() is None and not process_stopped(p.pid)]
        for pgid in pgids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pgid, signum)
        return list(pgids)

    def failure(self, line: str) -> None:
        """Say why the run is not whole; it ends with exit code 1."""
        self.failures.append(line)
        self.say(line)

    def reasons(self) -> list[str]:
        """Why the run ends with exit code 1, one phrase each: the nodes that died (not of a
        crash fault) and every failure said."""
        deaths = [
            f"node {name} (id {node_id}) {describe_exit(code)}"
            for name, node_id, code in self.deaths
            if code != CRASH_EXIT_CODE
        ]
        return deaths + self.failures

    def end_group(self, child: Child | ServiceChild | Share) -> None:
        """End what is left of a child's process group, once: its leader has exited (a PID,
        and so a group ID, may be reused once nothing holds it)."""
        if not child.group_ended:
            child.group_ended = True
            self._groups.end(child.process.pid)

    def request_stop(self, signum: int | None = None) -> None:
        if self._stop_signal is None:
            self._stop_signal = signum
        self._stop.set()

    def run(self, duration: float | None = None) -> int:
        """Supervise until the duration ends or a stop is requested; returns the exit code."""
        deadline = None if duration is None else time.monotonic() + duration
        while not self._stop.is_set():
            if deadline is not None and time.monotonic() >= deadline:
                break
            if (
                self.children
                and all(c.process.poll() is not None for c in self.child_list())
                and not self.respawn
            ):
                self.say("every node has exited")
                break
            self._stop.wait(0.1)
        self.stop()
        if self._stop_signal == signal.SIGINT:
            return 130
        unexpected = [d for d in self.deaths if d[2] != CRASH_EXIT_CODE]
        return 1 if unexpected or self.failures else 0

    def stop(self) -> None:
        """Stop every child: SIGTERM (clean leave), then SIGKILL whatever is left after 1.5 s."""
        self._stop.set()
        self._exits.wake()  # the supervisor sleeps on its children's exits
        if self._supervisor is None:
            self._exits.close_reading()  # never started
        elif self._supervisor is not threading.current_thread():
            self._supervision_ended.wait(timeout=1.0)
        if self._supervisor is None or self._supervision_ended.is_set():
            self._exits.close_waking()
        with self._children_lock:
            self.check_children()  # report what died before the stop
        running = [c for c in self.child_list() if c.process.poll() is None]
        if (running or self.hosts is not None) and self.session is not None and self.announce_stop:
            with contextlib.suppress(zenoh.ZError):  # nobody needs a handover: all are leaving
                self.session.put(keys.ring_event(self.ring), RING_EVENT.pack(EVENT_RING_STOPPING, 0, 0, 0, 0))
            time.sleep(0.02)
        if self.hosts is not None:
            self.hosts.begin_stop()  # the other hosts stop their nodes while this one does
        for child in running:
            with contextlib.suppress(ProcessLookupError):
                child.process.send_signal(signal.SIGTERM)
        # 255 nodes leaving at once on two cores need longer than the robot's eight
        stop_timeout = max(STOP_TIMEOUT_S, 0.02 * len(running))
        deadline = time.monotonic() + stop_timeout
        stubborn = []
        for child in running:
            try:
                child.process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                stubborn.append(child)
            child.reported = True
        if stubborn:  # all at once: a big ring on a loaded machine may have many of them
            names = ", ".join(c.plan.name for c in stubborn[:8]) + (" ..." if len(stubborn) > 8 else "")
            self.say(f"{len(stubborn)} node(s) did not stop in {stop_timeout:.1f} s: killing {names}")
            for child in stubborn:
                with contextlib.suppress(ProcessLookupError):
                    child.process.kill()
            reap_deadline = time.monotonic() + KILL_REAP_S
            for child in stubborn:
                try:
                    child.process.wait(max(0.1, reap_deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    self.say(f"node {child.plan.name} (pid {child.process.pid}) survived SIGKILL")
        for child in running:
            if child.process.poll() is not None:
                self.end_group(child)
        if self.hosts is not None:
            self.hosts.stop()
        self.service_supervisor.stop()
        # the supervisor, which may have started nodes and services again, outlives them
        self._children_gone.set()
        if self._booter is not None:
            self._booter.join(timeout=1.0)
        left = self._groups.finish(timeout=KILL_REAP_S)
        if left:
            self.say(f"processes the nodes or services started survived SIGKILL: pids {left}")
        self._groups.close()
        self.output.join_reader(timeout=1.0)
        for process in [c.process for c in self.child_list()] + list(self.service_children.values()):
            if process.stdout is not None:
                process.stdout.close()
        self.flush_output()
        if self.registry is not None:
            self.registry.close()
            self.registry = None
        if self._queryable is not None:
            with contextlib.suppress(zenoh.ZError):
                self._queryable.undeclare()
            self._queryable = None
        if self._stall_watch is not None:
            self._stall_watch.close()
            self._stall_watch = None
        if self._view_server is not None:
            self._view_server.close()
            self._view_server = None
        if self.session is not None:
            # Zenoh gives up closing a link whose far side is gone (a host cut off) after 10 s
            with contextlib.suppress(zenoh.ZError):
                self.session.close()
            self.session = None


class LauncherVerbs:
    """The launcher's control verbs on ``ctl/launcher/*``: ``status``, ``shutdown`` (the
    charger's deep-discharge cut), ``signal`` (how a SIGSTOPped node is resumed),
    ``programfailed`` (a node tells that its program raised: the run's exit code becomes 1)."""

    def __init__(self, launcher: Launcher) -> None:
        self.launcher = launcher
        self.handlers = {
            "status": lambda _: self.status(),
            "shutdown": self.shutdown,
            "signal": self.signal,
            "programfailed": self.program_failed,
        }

    def status(self) -> dict[str, Any]:
        """The ring, its endpoint and every node and service process."""
        launcher = self.launcher
        return {
            "ring": launcher.ring,
            "endpoint": launcher.endpoint,
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "started": launcher.started_at,
            "instance": launcher.instance,
            "booting": launcher.booting,
            "nodes": [
                {
                    "id": c.plan.node_id,
                    "name": c.plan.name,
                    "pid": c.process.pid,
                    "running": c.process.poll() is None,
                    "exit": describe_exit(c.process.poll()) if c.process.poll() is not None else None,
                    "restarts": c.restarts,
                }
                for c in launcher.child_list()
            ],
            "services": [
                {
                    "name": name,
                    "pid": p.pid,
                    "running": p.poll() is None,
                    "restarts": record.restarts
                    if (record := launcher.service_supervisor.records.get(name))
                    else 0,
                }
                for name, p in launcher.service_children.items()
            ],
            "hosts": launcher.hosts.status() if launcher.hosts is not None else [],
            "failures": list(launcher.failures),
        }

    def program_failed(self, request: dict[str, Any]) -> dict[str, Any]:
        """One of this launcher's nodes says its program raised (``setup()`` or ``run()``):
        one line naming the program and why, and the run ends with exit code 1. A node this
        launcher did not start (same ID, other PID) is not counted."""
        launcher = self.launcher
        try:
            node_id, pid = int(request.get("id", -1)), int(request.get("pid", -1))
        except (TypeError, ValueError):
            raise UsageError("programfailed needs the node's id and pid") from None
        child = launcher.children.get(node_id)
        if child is None or child.process.pid != pid:
            return {"counted": False}
        program = str(request.get("program") or "program")
        phase = str(request.get("phase") or "run")
        error = str(request.get("error") or "failed")
        how = "failed to load" if phase == "load" else f"failed in {phase}()"
        launcher.failure(f"program {program} on node {child.plan.name} (id {node_id}) {how}: {error}")
        return {"counted": True}

    def shutdown(self, request: dict[str, Any]) -> dict[str, Any]:
        """Stop the whole ring cleanly (the charger's deep-discharge cut asks for it)."""
        reason = str(request.get("reason", "asked to"))
        self.launcher.say(f"ring shutdown requested: {reason}")
        self.launcher.shutdown_reason = reason
        self.launcher.request_stop()
        return {"stopping": True}

    def signal(self, request: dict[str, Any]) -> dict[str, Any]:
        """Send a signal (CONT, STOP, TERM, KILL) to one of our nodes: how a SIGSTOPped node
        is resumed, since it can no longer answer anything itself."""
        name = str(request.get("signal", "")).upper().removeprefix("SIG")
        allowed = {
            "CONT": signal.SIGCONT,
            "STOP": signal.SIGSTOP,
            "TERM": signal.SIGTERM,
            "KILL": signal.SIGKILL,
        }
        if name not in allowed:
            raise UsageError(f"signal must be one of {', '.join(allowed)}")
        child = self.launcher.children.get(int(request.get("id", -1)))
        if child is None or child.process.poll() is not None:
            raise UsageError(f"node {request.get('id')} is not a running node of this launcher")
        os.kill(child.process.pid, allowed[name])
        return {"id": child.plan.node_id, "pid": child.process.pid, "signal": name}


def plans_from_protocol(
    protocol: Any, selection: Sequence[str] | None, programs_dir: str | Path | None
) -> list[NodePlan]:
    """Nodes to start: the ``--nodes`` selection (names or IDs), or without one protocol.yaml's
    nodes but the optional ones."""
    if selection:
        specs = []
        for item in selection:
            try:
                specs.append(protocol.node(int(item) if item.isdigit() else item))
            except Exception as exc:
                raise UsageError(str(exc)) from None
    else:
        specs = list(protocol.default_nodes)
    plans = []
    seen: set[int] = set()
    for spec in specs:
        if spec.id in seen:
            continue
        seen.add(spec.id)
        program = None
        if programs_dir is not None:
            candidate = Path(programs_dir) / f"{spec.name}.py"
            if candidate.exists():
                program = str(candidate)
        plans.append(NodePlan(spec.id, spec.name, program))
    return sorted(plans, key=lambda p: p.node_id)


def install_signal_handlers(launcher: Launcher) -> None:
    """SIGINT, SIGTERM and SIGHUP (a closed terminal) stop the ring cleanly; Ctrl-Z (SIGTSTP)
    suspends it whole: the children lead process groups of their own, out of the terminal's
    reach, so the launcher stops and continues them itself."""

    def handler(signum: int, _frame: Any) -> None:
        launcher.request_stop(signum)

    def suspend(_signum: int, _frame: Any) -> None:
        stopped = launcher.signal_groups(signal.SIGSTOP)
        # SIGSTOP, not SIGTSTP again: the kernel drops a default-handled SIGTSTP to a process of
        # an orphaned group (a launcher started by a script or service), and the launcher would
        # leave its nodes stopped and run on
        os.kill(os.getpid(), signal.SIGSTOP)  # stops here until the shell continues us
        launcher.signal_groups(signal.SIGCONT, stopped)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGHUP, handler)
    signal.signal(signal.SIGTSTP, suspend)
