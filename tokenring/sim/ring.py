"""A ring in virtual time: the node OS on the memory hub, run by a :class:`SimRuntime` (issue 55).

The very nodes ``tokenring up`` starts as processes (the Python token path), built inside one
simulation: every wait is the runtime's, the wire's hop time moves the virtual clock, and every
frame the hub delivers goes into one SHA-256 (``frames_sha256``). The same nodes, options and seed
give the same hash, run after run, on any host.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from tokenring import runtime
from tokenring.contract.protocol import Protocol
from tokenring.errors import UsageError
from tokenring.node.channels import CommandMemory
from tokenring.node.faults import FaultInjector
from tokenring.node.node_os import NodeOS
from tokenring.node.pacing import install as install_profile
from tokenring.node.store import ProgramStore
from tokenring.node.system.layer import SystemLayer
from tokenring.runtime import SimRuntime, using
from tokenring.transport.memory import MemoryHub, MemoryTransport


@dataclass
class SimSummary:
    """What one run in virtual time did (``--json``)."""

    seed: int
    nodes: list[int]
    bitrate: float
    profile: str | None
    simulated_s: float
    real_s: float
    frames: int
    frames_sha256: str
    visits: dict[int, int]
    #: tokens the nodes made: the ring's first one too (no token seen yet, as at any start)
    regenerations: int
    round_median_ms: float | None
    switches: int
    #: the ``--fault`` requests as applied, each with its recovery (``recovered_s``: from the
    #: fault to the ring circulating again; the regenerations in between): tokenring.sim.faults
    faults: list[dict[str, Any]] = field(default_factory=list)
    #: what the nodes' fault injectors did (dropped, corrupted, ...), by node
    fault_counts: dict[str, dict[str, int]] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    #: of those, the ones that replaced a token the ring had had (lost, or thought lost)
    reconfigurations: int = 0

    @property
    def speedup(self) -> float:
        """Simulated seconds per real second."""
        return self.simulated_s / self.real_s if self.real_s > 0 else float("inf")

    def as_dict(self) -> dict[str, Any]:
        return {
            **asdict(self),
            "speedup": round(self.speedup, 2),
            "visits": {str(k): v for k, v in self.visits.items()},
        }


class SimRing:
    """The nodes of one simulated ring on their hub (built inside the simulation)."""

    def __init__(
        self,
        protocol: Protocol,
        ids: Sequence[int],
        bitrate: float,
        profile: str | None,
        ack_mode: str = "adaptive",
    ) -> None:
        self.protocol = protocol
        self.bitrate = bitrate
        self.profile = profile
        self.ack_mode = ack_mode
        self.hub = MemoryHub()
        self.hub.hash_frames()
        #: the nodes' stores (battery-backed RAM), which outlive a crash: a node process keeps
        #: what its inbox took there (tokenring.node.process), so a respawned node does too
        self.store = Path(tempfile.mkdtemp(prefix="tokenring-sim-store-"))
        self._remove_store = weakref.finalize(self, shutil.rmtree, self.store, True)
        self.nodes: dict[int, NodeOS] = {}
        #: each node's system commands (scan, download, start, stop), as its process has them,
        #: its program in its store
        self.systems: dict[int, SystemLayer] = {}
        for node_id in ids:
            self.nodes[node_id] = self._boot(node_id)
        #: each node's own fault injector, as its process has one (``tokenring fault``'s path);
        #: made after every node started, its draws come from the simulation's seed
        self.faults = {node_id: FaultInjector(node) for node_id, node in self.nodes.items()}

    def _boot(self, node_id: int) -> NodeOS:
        node = NodeOS(
            self.protocol,
            node_id,
            MemoryTransport(self.hub, "sim", node_id),
            bitrate=self.bitrate,
            ack_mode=self.ack_mode,
        )
        node.command_memory = CommandMemory(self.store / node.name / "inbox-memory")
        install_profile(node, self.profile, self.bitrate, node._now())
        self.systems[node_id] = SystemLayer(
            node, store=ProgramStore(self.store / node.name, node.name)
        ).install()
        node.start()
        return node

    def kill(self, node_id: int) -> None:
        """The node's process dies at once (a crash): it vanishes from the wire and stops, no
        goodbye. Its program is stopped too; what a program may still write as it stops is its
        own to suppress (a killed process writes nothing)."""
        node = self.nodes[node_id]
        node.paused = True  # a dead process's watchdog regenerates nothing
        self.hub.crash(node_id)
        node.command_memory.close()  # its store keeps what it wrote; the process writes no more
        system = self.systems[node_id]

        def end() -> None:
            system.close()
            node.close()

        # its threads end in a task of their own: the killer's time does not pass meanwhile
        runtime.current().spawn(end, f"kill-{node_id}")

    def respawn(self, node_id: int) -> NodeOS:
        """A new process for a killed node (the launcher's respawn): a fresh node OS and fault
        injector under the same ID."""
        node = self._boot(node_id)
        self.nodes[node_id] = node
        self.faults[node_id] = FaultInjector(node)
        return node

    def close(self) -> None:
        for node_id, node in self.nodes.items():
            self.systems[node_id].close()
            node.close()
            node.command_memory.close()
        self._remove_store()


class _VirtualTime(logging.Filter):
    """Log records stamped with the simulation's clock (its wall clock starts in 2001), so a
    run's log reads the same every time."""

    def __init__(self, sim: SimRuntime) -> None:
        super().__init__()
        self.sim = sim

    def filter(self, record: logging.LogRecord) -> bool:
        record.created = self.sim.time()
        record.msecs = (record.created % 1.0) * 1000.0
        return True


Scenario = Callable[[SimRuntime, SimRing], dict[str, Any]]


def run_ring(
    protocol: Protocol,
    ids: Sequence[int],
    *,
    seed: int,
    duration_s: float,
    bitrate: float | None,
    profile: str | None = None,
    scenario: Scenario | None = None,
    ack_mode: str = "adaptive",
) -> SimSummary:
    """Run the ring ``ids`` for ``duration_s`` of virtual time (or ``scenario``, which gets the
    runtime and the ring and returns facts for the summary)."""
    if bitrate is None:
        raise UsageError(
            "--bitrate max has no wire time: in virtual time nothing would ever move the clock on "
            "(give a bitrate, e.g. 2.5M, the ARCNET robot's)"
        )
    before = set(threading.enumerate())
    sim = SimRuntime(seed)

    def main() -> SimSummary:
        ring = SimRing(protocol, ids, bitrate, profile, ack_mode)
        extra = scenario(sim, ring) if scenario is not None else {}
        if scenario is None:
            sim.sleep(duration_s)
        first = ring.nodes[min(ring.nodes)]
        median = first.timing.round_median
        summary = SimSummary(
            seed=seed,
            nodes=sorted(ring.nodes),
            bitrate=bitrate,
            profile=profile,
            simulated_s=sim.now,
            real_s=0.0,
            frames=ring.hub.frames_delivered,
            frames_sha256=ring.hub.digest.hexdigest() if ring.hub.digest is not None else "",
            visits={i: n.stats.visits for i, n in ring.nodes.items()},
            regenerations=sum(n.stats.tokens_regenerated for n in ring.nodes.values()),
            reconfigurations=sum(n.stats.reconfigurations for n in ring.nodes.values()),
            round_median_ms=None if median is None else round(median * 1000.0, 6),
            switches=sim.switches,
            faults=extra.pop("faults", []),
            fault_counts=extra.pop("fault_counts", {}),
            extra=extra,
        )
        ring.close()
        return summary

    started = time.perf_counter()
    stamp = _VirtualTime(sim)
    handlers = logging.getLogger().handlers
    for handler in handlers:
        handler.addFilter(stamp)
    with using(sim):
        try:
            summary = sim.run(main)
        finally:
            left = sim.close()
            for handler in handlers:
                handler.removeFilter(stamp)
    summary.real_s = round(time.perf_counter() - started, 6)
    stray = [t.name for t in set(threading.enumerate()) - before]
    if left or stray:
        raise RuntimeError(f"the simulation left threads behind: {left or stray}")
    return summary
