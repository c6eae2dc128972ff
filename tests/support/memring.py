"""An in-process ring on the memory transport, for fast tests of the ring and channel logic."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable

from tokenring import runtime
from tokenring.contract.protocol import Protocol, default_protocol
from tokenring.node.node_os import NodeOS
from tokenring.transport.memory import MemoryHub, MemoryTransport


def wait_for(condition: Callable[[], object], timeout: float = 5.0, what: str = "condition") -> object:
    """Poll ``condition`` until it is truthy; fail with ``what`` after ``timeout`` seconds (of
    the runtime in force: virtual ones in a simulation)."""
    rt = runtime.current()
    deadline = rt.monotonic() + timeout
    while rt.monotonic() < deadline:
        value = condition()
        if value:
            return value
        rt.sleep(0.002)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def in_virtual_time(seed: int = 1) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Run a test's body on a simulated runtime (:class:`tokenring.runtime.SimRuntime`): every
    ring it builds runs on the virtual clock, deterministic for ``seed``, and no task may be left
    when it returns. Fixtures it takes are made outside the simulation: a ring must be built in
    the body."""
    import functools

    def decorate(test: Callable[..., None]) -> Callable[..., None]:
        @functools.wraps(test)  # pytest still sees the test's own fixtures (tmp_path, ...)
        def run(*args: object, **kwargs: object) -> None:
            from tokenring.runtime import SimRuntime, using

            sim = SimRuntime(seed)
            with using(sim):
                try:
                    sim.run(lambda: test(*args, **kwargs))
                finally:
                    left = sim.close()
            assert left == [], f"tasks left running: {left}"

        return run

    return decorate


# node processes hand the GIL over every 0.5 ms (tokenring.node.process); eight in-process nodes
# need the same, or one node waits 5 ms per switch behind the others
sys.setswitchinterval(0.0005)


class MemoryRing:
    """A set of NodeOS instances sharing one MemoryHub; made inside a simulation (under
    ``runtime.using(sim)``, in ``sim.run``) it runs on the simulation's virtual clock."""

    def __init__(
        self, ids: Iterable[int] | None = None, protocol: Protocol | None = None, **node_options
    ) -> None:
        self.protocol = protocol or default_protocol()
        self.hub = MemoryHub()
        self.options = node_options
        self.nodes: dict[int, NodeOS] = {}
        for node_id in ids if ids is not None else [n.id for n in self.protocol.default_nodes]:
            self.add(node_id)

    def add(self, node_id: int) -> NodeOS:
        node = NodeOS(self.protocol, node_id, MemoryTransport(self.hub, "mem", node_id), **self.options)
        node.start()
        self.nodes[node_id] = node
        return node

    def freeze(self, node_id: int, frozen: bool = True) -> None:
        """Like SIGSTOP/SIGCONT: deliveries, sends and the node's watchdog all stand still."""
        self.nodes[node_id].paused = frozen
        self.hub.freeze(node_id, frozen)

    def by_name(self, name: str) -> NodeOS:
        return self.nodes[self.protocol.node(name).id]

    def wait_rounds(self, rounds: int, node_id: int | None = None, timeout: float = 5.0) -> None:
        node = self.nodes[node_id if node_id is not None else min(self.nodes)]
        start = node.stats.visits
        wait_for(lambda: node.stats.visits >= start + rounds, timeout, f"{rounds} rounds")

    def regenerated(self) -> int:
        return sum(n.stats.tokens_regenerated for n in self.nodes.values())

    def close(self) -> None:
        for node in self.nodes.values():
            node.close()
