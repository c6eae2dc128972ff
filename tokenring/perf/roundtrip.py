"""``tokenring bench``: token round trips of the real ring against a bare Zenoh ring.

Both rings have N processes on this machine and are measured in the same run (alternating when
``--repeat`` > 1), so the ratio is meaningful even where absolute times are noisy. The ring's
round trip is timed by its round master (the time between two of its visits); the baseline's by
its process 0. Reports median, p90, p99 and max, per-hop cost, handler time (from the token's
arrival to the put that passes it on), RSS and CPU.
"""

from __future__ import annotations

import io
import itertools
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tokenring._util.process import die_with_parent
from tokenring.contract import keys
from tokenring.errors import TokenRingError, UsageError
from tokenring.host.children import ExitWatch
from tokenring.host.launcher import Launcher, NodePlan
from tokenring.observe.pcap_tap import WireTap
from tokenring.transport.session import free_port, query
from tokenring.transport.zenoh_config import hop_callback, make_config, node_environment, open_session

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def generated_ids(n: int) -> list[int]:
    """``n`` node IDs spread over 1..255 (so new nodes could fit between, as in protocol.yaml)."""
    if not 2 <= n <= 255:
        raise UsageError(f"--nodes must be 2..255, not {n}")
    if n == 255:
        return list(range(1, 256))
    ids = sorted({round(1 + i * 254 / (n - 1)) for i in range(n)})
    return ids


def summarize(seconds: list[float] | np.ndarray) -> dict[str, float]:
    values = np.asarray(seconds) * 1e3
    if not len(values):
        return {
            "median": float("nan"),
            "p90": float("nan"),
            "p99": float("nan"),
            "max": float("nan"),
            "n": 0,
        }
    return {
        "median": float(np.median(values)),
        "p90": float(np.percentile(values, 90)),
        "p99": float(np.percentile(values, 99)),
        "max": float(values.max()),
        "mean": float(values.mean()),
        "n": len(values),
    }


def proc_memory_mb(pid: int) -> tuple[float, float]:
    """The process's RSS and USS in MB (USS: its private pages, what stopping it gives back);
    NaN for a figure that cannot be read."""
    from tokenring._util.process_memory import memory_kb

    kb = memory_kb(pid)
    rss, uss = (kb[k] / 1024 if kb[k] >= 0 else float("nan") for k in ("rss_kb", "uss_kb"))
    return rss, uss


def proc_cpu_s(pid: int) -> float:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS
    except (OSError, IndexError, ValueError):
        return float("nan")


def progress(text: str, quiet: bool = False) -> None:
    if not quiet:
        sys.stderr.write(text + "\n")
        sys.stderr.flush()


# ---------------------------------------------------------------------------------------------


def spawn_bare_ring(
    n: int,
    port: int,
    ring: str,
    rounds: int,
    warmup: int,
    timeout: float,
    *,
    router: bool,
    stamps: bool = False,
    chain: bool = False,
    stdout: Any = subprocess.PIPE,
    stderr: Any = None,
) -> tuple[subprocess.Popen, list[subprocess.Popen]]:
    """Start the ``n`` processes of a bare Zenoh ring (``tokenring.perf.bare_ring``) on ``port``:
    process 0, whose stdout carries the result line, and the others. They run the ring's Zenoh
    runtime and, like the launcher's nodes, die with a benchmark that is killed. With ``router``
    the caller has opened the router on ``port``; ``stamps``: process 0 also prints each round's
    arrival time; ``chain``: each process linked to its successor only, on ports of its own (with
    ``router`` also a client of the router in a second session: ``roundtrip_bare --mode links``).
    ``stdout``: process 0's; ``stderr``: every process's."""
    base = [sys.executable, "-m", "tokenring.perf.bare_ring", "--count", str(n), "--port", str(port)]
    base += ["--rounds", str(rounds), "--warmup", str(warmup), "--ring", ring, "--timeout", str(timeout)]
    mode = ("links" if router else "chain") if chain else "client" if router else "peer"
    base += ["--mode", mode] + (["--stamps"] if stamps else [])
    if chain:
        ports: list[int] = []
        for _ in range(n):
            ports.append(free_port(avoid=ports))
        base += ["--ports", ",".join(map(str, ports))]
    env = node_environment()  # the same Zenoh runtime as the ring's nodes
    first = subprocess.Popen(
        [*base, "--index", "0"], stdout=stdout, stderr=stderr, text=True, env=env, preexec_fn=die_with_parent
    )
    others = [
        subprocess.Popen(
            [*base, "--index", str(i)],
            stdout=subprocess.DEVNULL,
            stderr=stderr,
            env=env,
            preexec_fn=die_with_parent,
        )
        for i in range(1, n)
    ]
    return first, others


def run_bare(
    n: int, rounds: int, warmup: int, timeout: float = 120.0, *, router: bool = False, chain: bool = False
) -> list[float]:
    """Round times (s) of a bare Zenoh ring of ``n`` processes: a full mesh of peers, with
    ``router`` every process a client of a Zenoh router opened here (as the launcher does), with
    ``chain`` every process a peer linked to its successor only (a topology the ring has not),
    with both the chain plus a client session of the router in every process."""
    port = free_port()
    router_session = (
        open_session(make_config(mode="router", listen=[f"tcp/127.0.0.1:{port}"])) if router else None
    )
    with tempfile.TemporaryFile("w+") as out_file, tempfile.TemporaryFile("w+") as err_file:
        first, others = spawn_bare_ring(
            n,
            port,
            f"b{os.getpid()}x{port}",
            rounds,
            warmup,
            timeout,
            router=router,
            chain=chain,
            stdout=out_file,
            stderr=err_file,
        )
        try:
            failed = _wait_first(first, others, timeout + 30)
        finally:
            end_all(others, grace_s=10.0)
            if first.poll() is None:
                first.kill()
                first.wait(2)
            if router_session is not None:
                router_session.close()
        out_file.seek(0)
        out = out_file.read()
        if failed is not None:
            err_file.seek(0)
            said = [line.strip() for line in err_file.read().splitlines() if line.strip()]
            why = f": {said[-1][:300]}" if said else ""
            raise TokenRingError(
                f"bare ring of {n}: process {failed[0]} ended with exit code {failed[1]} before "
                f"the rounds were done{why}"
            )
    lines = [line for line in out.splitlines() if line.startswith("{")]
    if not lines:
        raise TokenRingError(f"the bare ring of {n} produced no result")
    result = json.loads(lines[-1])
    if "error" in result:
        raise TokenRingError(f"bare ring of {n}: {result['error']}")
    return result["rounds_s"]


def end_all(processes: list[subprocess.Popen], grace_s: float) -> None:
    """Give ``processes`` one shared ``grace_s`` to end on their own, then kill the rest (waiting
    a few seconds for each in turn had a stalled 255-process ring hold a run for 15 minutes)."""
    deadline = time.monotonic() + grace_s
    for proc in processes:
        try:
            proc.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
    for proc in processes:
        proc.wait()


def _wait_first(
    first: subprocess.Popen, others: list[subprocess.Popen], timeout: float
) -> tuple[int, int] | None:
    """Wait for process 0 of a bare ring to end; (index, exit code) of a process that failed
    first (the ring can no longer go round: stop waiting at once), None if none did. Woken by
    the processes' exits (pidfds, as the launcher's supervisor is), not by polling 255 of them
    from beside the ring being measured."""
    watch = ExitWatch()
    for proc in (first, *others):
        watch.add(proc.pid, proc.pid)
    deadline = time.monotonic() + timeout
    try:
        while first.poll() is None:
            failed = next(
                ((i, p.returncode) for i, p in enumerate(others, 1) if p.poll() not in (None, 0)), None
            )
            if failed is not None:
                return failed
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            watch.wait(left if watch.works else min(left, 0.2))
    finally:
        watch.close_reading()
        watch.close_waking()
    return (0, first.returncode) if first.returncode not in (0, 1) else None


@dataclass
class RingRun:
    rounds_s: list[float]
    rss_mb: list[float]
    cpu_s: list[float]
    handler_us: dict[str, float]
    wall_s: float
    stats: dict[str, Any] = field(default_factory=dict)
    launcher_cpu_s: float = 0.0  # the launcher process: the Zenoh router, the registry
    form_s: float = 0.0  # from the first process started to the ring circulating through all
    uss_mb: list[float] = field(default_factory=list)  # per node, beside ``rss_mb``
    #: round times (s) seen from outside: the arrivals of the frames sent to the round master at
    #: a subscriber in this process, over the same window (empty unless ``run_ring(tap=True)``)
    tap_rounds_s: list[float] = field(default_factory=list)
    #: packets the wire tap's kernel buffer lost (direct links; its rounds skip the gaps)
    tap_dropped: int = 0


def wire_rounds(frames: list[tuple[float, bytes]], master: int) -> list[float]:
    """Round times (s) from frames captured on the wire: between fresh frames into ``master``
    whose round counter moved on by one (a retransmission repeats a frame, a frame the capture
    lost leaves a gap: neither becomes a round)."""
    from tokenring.observe.capture import passes

    into = [p for p in passes(frames)[0] if p.did == master]
    return [b.t - a.t for a, b in itertools.pairwise(into) if (b.counter - a.counter) & 0xFF == 1]


def run_ring(
    n: int,
    rounds: int,
    warmup: int,
    *,
    bitrate: str = "max",
    ack_mode: str = "adaptive",
    timeout: float = 120.0,
    programs: dict[int, str] | None = None,
    ids: list[int] | None = None,
    extra_node_args: list[str] | None = None,
    router: bool = False,
    links: bool = False,
    transport: str = "zenoh",
    profile: str | None = None,
    plans: list[NodePlan] | None = None,
    services: list[Any] | None = None,
    master: int | None = None,
    ring: str | None = None,
    on_ready: Callable[[Any, str], None] | None = None,
    tap: bool = False,
) -> RingRun:
    """Round times (s) of the real ring of ``n`` node processes, with RSS and CPU per node.

    ``router``: the launcher's session is a Zenoh router and the nodes its clients (else a full
    mesh of peers); ``links``: with the router, each node's token hop also on a direct link to
    its successor (``Launcher(links=True)``); ``transport``: what carries the token (zenoh, udp,
    zmq); ``profile``: an emulated hardware timing; ``plans``/``services``: named nodes with programs and helper
    processes (the robot), instead of ``n`` generated IDs; ``tap``: also time the rounds from
    outside, by the arrivals of the master's frames at a subscriber of this process (on direct
    links, where no subscriber sees them, at the master's link port on the wire: :mod:`tokenring.observe.pcap_tap`).
    """
    # a ring of generated IDs is the ring alone: its node 70 must not boot as the robot's lcd,
    # whose resident program (the boot menu, with numpy and Pillow) made it a 58 MB node
    residents = plans is not None
    if plans is None:
        ids = ids or generated_ids(n)
        plans = [NodePlan(i, f"node{i}", (programs or {}).get(i)) for i in ids]
    ids = [p.node_id for p in plans]
    port = free_port()
    ring = ring or f"r{os.getpid()}x{port}"
    launcher = Launcher(
        plans,
        ring=ring,
        bitrate=bitrate,
        ack_mode=ack_mode,
        listen=[f"tcp/127.0.0.1:{port}"],
        log_level="warning",
        output=io.StringIO(),
        extra_node_args=extra_node_args or [],
        router=router,
        links=links,
        transport=transport,
        profile=profile,
        services=services or [],
        residents=residents,
    )
    from tokenring.contract.protocol import default_protocol

    if master is None:
        main_id = default_protocol().nodes["main"].id if "main" in default_protocol().nodes else None
        master = main_id if main_id in ids else min(ids)
    t_start = time.monotonic()
    wire_tap: WireTap | None = None
    launcher.start()
    try:
        config = make_config(mode="client" if router else "peer", connect=[f"tcp/127.0.0.1:{port}"])
        with open_session(config) as session:
            key = keys.control(ring, master, "stats")
            deadline = time.monotonic() + timeout
            stats: dict[str, Any] = {}
            formed = 0.0
            while time.monotonic() < deadline:
                answer = master_answer(session, key, timeout=1.0)
                if answer is not None:
                    stats = answer
                    if len(stats["active"]) == len(ids):
                        formed = formed or time.monotonic()
                        if stats["stats"]["visits"] >= warmup:
                            break
                dead = [c for c in launcher.child_list() if c.process.poll() is not None]
                if dead:
                    raise TokenRingError(f"node {dead[0].plan.name} died while the ring formed")
                time.sleep(0.1)
            else:
                raise TokenRingError(
                    f"ring of {n} did not form in {timeout:.0f} s "
                    f"(active {len(stats.get('active', []))}, visits {stats.get('stats', {}).get('visits', 0)})"
                )
            arrivals: list[float] = []
            tap_dropped = 0
            wire_tap = WireTap.into(launcher.link_ports[master]) if tap and links else None
            if wire_tap is not None:  # on direct links no subscriber sees the token: the wire
                wire_tap.start()
            tap_subscriber = (
                session.declare_subscriber(
                    keys.token(ring, master),
                    hop_callback(lambda _sample: arrivals.append(time.perf_counter())),
                )
                if tap and wire_tap is None
                else None
            )
            cpu0 = {c.process.pid: proc_cpu_s(c.process.pid) for c in launcher.child_list()}
            own_cpu = time.process_time()
            t0 = time.monotonic()
            start_visits = stats["stats"]["visits"]
            visits_key = keys.control(ring, master, "visits")
            if tap:  # count the rounds from when the tap listens (tcpdump takes ~0.1-1 s to start)
                answer = master_answer(session, visits_key, timeout=1.0)
                start_visits = start_visits if answer is None else answer
            while time.monotonic() < deadline:
                time.sleep(0.2)
                visits = master_answer(session, visits_key, timeout=1.0)  # cheap: one integer
                if visits is not None and visits >= start_visits + rounds:
                    break
            else:
                raise TokenRingError(f"ring of {n}: measurement did not finish in {timeout:.0f} s")
            wall = time.monotonic() - t0
            # the rounds first, then what reads the nodes from outside: reading 255 processes'
            # /proc (smaps_rollup walks each one's page tables under its memory lock) slowed the
            # rounds it overlapped, and those were the last rounds measured (3 of 150 per run)
            asked = time.perf_counter()  # the master's last round ends about here: the tap's too
            round_list = ask_master(session, keys.control(ring, master, "rounds"))
            if on_ready is not None:  # e.g. collect what programs measured, while the ring runs
                on_ready(session, ring)
            launcher_cpu = time.process_time() - own_cpu
            cpu = [proc_cpu_s(c.process.pid) - cpu0[c.process.pid] for c in launcher.child_list()]
            memory = [proc_memory_mb(c.process.pid) for c in launcher.child_list()]
            rss, uss = [m[0] for m in memory], [m[1] for m in memory]
            stats = ask_master(session, key)
            if tap_subscriber is not None:
                tap_subscriber.undeclare()
            before = [t for t in arrivals if t <= asked]
            tap_rounds_s = [b - a for a, b in itertools.pairwise(before)][-rounds:]
            if wire_tap is not None:  # (it catches up past ``asked`` first; later frames go)
                frames = [f for f in wire_tap.stop() if f[0] <= asked]
                tap_rounds_s = wire_rounds(frames, master)[-rounds:]
                tap_dropped = wire_tap.dropped
            return RingRun(
                round_list[-rounds:],
                rss,
                cpu,
                stats["handler_us"],
                wall,
                stats,
                launcher_cpu_s=launcher_cpu,
                form_s=formed - t_start if formed else float("nan"),
                uss_mb=uss,
                tap_rounds_s=tap_rounds_s,
                tap_dropped=tap_dropped,
            )
    finally:
        if wire_tap is not None:
            wire_tap.stop()  # (again: a run that failed leaves no capture behind)
        launcher.stop()


# ---------------------------------------------------------------------------------------------


def master_answer(session: Any, key: str, timeout: float) -> Any | None:
    """The first good answer on control ``key`` within ``timeout`` s, or None."""
    replies = query(session, key, timeout=timeout)
    return replies[0][1]["result"] if replies and replies[0][1].get("ok") else None


def ask_master(session: Any, key: str, attempts: int = 3) -> Any:
    """The master's answer on control ``key``, asked up to ``attempts`` times (2 s each): on a
    loaded machine one query can go unanswered; raises :class:`TokenRingError` if all do."""
    for _ in range(attempts):
        answer = master_answer(session, key, timeout=2.0)
        if answer is not None:
            return answer
    raise TokenRingError(f"the round master did not answer {key} ({attempts} times)")


def run_budget(nodes: int, rounds: int, bitrate: float | None) -> float:
    """Seconds a run of ``rounds`` may take: forming plus 1 ms per hop (a 255-node round is ~80 ms
    on two cores) plus the emulated wire time; a fixed 120 s failed 2000 rounds of 255 nodes."""
    from tokenring.contract.ring import hop_time

    return 120.0 + rounds * nodes * (0.001 + hop_time(bitrate))
