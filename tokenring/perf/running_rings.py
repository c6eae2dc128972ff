"""Rings that run until told to stop: a bare Zenoh ring and a tokenring ring, side by side.

The measures that look inside a running ring (the interleaved own share of
:mod:`tokenring.perf.interleaved_pairs`, ``bench.hopcost``'s thread samples) need rings that keep
circulating while they are watched, paused and resumed, rather than :mod:`tokenring.perf.roundtrip`'s
runs of a fixed number of rounds. Both classes start their processes as ``tokenring bench`` does
and give their PIDs.
"""

from __future__ import annotations

import io
import json
import os
import select
import subprocess
import time
from typing import Any

from tokenring.errors import TokenRingError


class BareRing:
    """A bare Zenoh ring that runs until told to stop, then reports each round's arrival time
    (CLOCK_MONOTONIC, the clock of this process's ``time.monotonic`` and ``perf_counter``)."""

    def __init__(self, nodes: int, router: bool, chain: bool = False) -> None:
        from tokenring.perf.roundtrip import end_all, spawn_bare_ring
        from tokenring.transport.session import free_port
        from tokenring.transport.zenoh_config import make_config, open_session

        port = free_port()
        ring = f"h{os.getpid()}x{port}"
        self.prefix = f"tokenring-bare/{ring}"
        self.router = (
            open_session(make_config(mode="router", listen=[f"tcp/127.0.0.1:{port}"])) if router else None
        )
        connect = make_config(mode="client" if router else "peer", connect=[f"tcp/127.0.0.1:{port}"])
        # runs until stop(): rounds enough for any window
        self.first, self.others = spawn_bare_ring(
            nodes, port, ring, 10_000_000, 50, 3600, router=router, stamps=True, chain=chain
        )
        self.pids = [self.first.pid] + [p.pid for p in self.others]
        try:
            self.session = open_session(connect)
        except BaseException:
            end_all([self.first, *self.others], grace_s=1.0)
            if self.router is not None:
                self.router.close()
            raise

    def wait_circulating(self, timeout: float) -> None:
        """Until the token has gone round its warm-up rounds (process 0 says so on its stdout: on
        direct links no subscriber here sees the token)."""
        deadline = time.monotonic() + timeout
        assert self.first.stdout is not None
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or self.first.poll() is not None:
                raise TokenRingError(
                    f"the bare ring of {len(self.pids)} did not circulate within {timeout:.0f} s"
                )
            readable, _, _ = select.select([self.first.stdout], [], [], left)
            if readable and '"warm"' in self.first.stdout.readline():
                return

    def stop(self) -> list[float]:
        """Stop every process; the arrival times process 0 recorded."""
        from tokenring.perf.roundtrip import end_all

        self.session.put(f"{self.prefix}/stop", b"")
        try:
            out, _ = self.first.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            self.first.kill()
            out, _ = self.first.communicate()
        end_all(self.others, grace_s=10.0)
        self.session.close()
        if self.router is not None:
            self.router.close()
        lines = [line for line in out.splitlines() if line.startswith("{")]
        return json.loads(lines[-1]).get("stamps_s", []) if lines else []


class LiveRing:
    """A tokenring ring of ``nodes`` generated node IDs, launched as ``tokenring bench`` launches
    it (``router``: the nodes clients of a router in this process; ``links``: with direct links to
    their successors too), whose round master answers queries until :meth:`stop`."""

    def __init__(
        self,
        nodes: int,
        router: bool,
        links: bool = False,
        bitrate: str = "max",
        ack_mode: str = "adaptive",
    ) -> None:
        from tokenring.host.launcher import Launcher, NodePlan
        from tokenring.perf.roundtrip import generated_ids
        from tokenring.transport.session import free_port
        from tokenring.transport.zenoh_config import make_config, open_session

        ids = generated_ids(nodes)
        port = free_port()
        self.ring = f"h{os.getpid()}x{port}"
        self.master = min(ids)
        self.output = io.StringIO()  # the nodes' warnings, for a caller that wants to see them
        self.launcher = Launcher(
            [NodePlan(i, f"node{i}", None) for i in ids],
            ring=self.ring,
            bitrate=bitrate,
            ack_mode=ack_mode,
            listen=[f"tcp/127.0.0.1:{port}"],
            log_level="warning",
            output=self.output,
            router=router,
            links=links,
        )
        self.launcher.start()
        try:
            config = make_config(mode="client" if router else "peer", connect=[f"tcp/127.0.0.1:{port}"])
            self.session = open_session(config)
        except BaseException:
            self.launcher.stop()
            raise

    @property
    def pids(self) -> list[int]:
        """The node processes' PIDs."""
        return [c.process.pid for c in self.launcher.child_list()]

    def answer(self, what: str, timeout: float = 2.0) -> Any | None:
        """The round master's answer on its control key ``what`` (visits, rounds, stats), or None."""
        from tokenring.contract import keys
        from tokenring.perf.roundtrip import master_answer

        return master_answer(self.session, keys.control(self.ring, self.master, what), timeout)

    def visits(self) -> int:
        """The round master's visits so far; -1 if it did not answer."""
        answer = self.answer("visits")
        return int(answer) if answer is not None else -1

    def wait_circulating(self, timeout: float, visits: int = 100) -> None:
        """Until the round master has had ``visits`` visits."""
        deadline = time.monotonic() + timeout
        while self.visits() < visits:
            if time.monotonic() > deadline:
                raise TokenRingError(f"the ring {self.ring} did not circulate within {timeout:.0f} s")
            time.sleep(0.1)

    def stop(self) -> None:
        """Close this process's session and stop every node."""
        self.session.close()
        self.launcher.stop()
