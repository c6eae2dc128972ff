"""A randomized nemesis for ``tokenring chaos --random SEED``: schedules drawn from a seed, and
a shrinker that cuts a failing schedule down to a small one that still fails.

Like Jepsen's generators, the schedule is data: :func:`generate` draws *operations* — a fault
and, where it has one, the step that ends it (hang/resume, leave/join, partition/heal,
delay|drop|corrupt|duplicate/clear; crash and lose end by themselves) — on any node, main and
neighbours included, overlapping, several at once, some during the recovery from the last, and
crash loops. The same seed gives the same schedule; it is written out as an ordinary scenario
file, so a run can be repeated with ``tokenring chaos FILE``. :func:`shrink` removes operations
(never half of one) while the run still fails, like delta debugging.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import yaml

from tokenring.chaos.operations import OPERATIONS

MAX_DOWN = 3  # at most this many nodes hung, left or restarting at once (of the ring's nodes)
RESPAWN_S = 2.5  # how long a crashed node is left alone while it restarts


@dataclass(frozen=True)
class Operation:
    """A fault and the steps that end it: removed or kept together when shrinking."""

    steps: tuple[dict[str, Any], ...]

    @property
    def start(self) -> float:
        return float(self.steps[0]["at"])


def generate(
    seed: int,
    nodes: Sequence[str],
    *,
    duration: float = 60.0,
    settle: float = 3.0,
    kinds: Sequence[str] = OPERATIONS,
) -> list[Operation]:
    """Draw a schedule of overlapping operations on ``nodes`` for ``duration`` seconds."""
    rng = random.Random(seed)
    last_end = max(1.0, duration - settle)
    busy: dict[str, float] = dict.fromkeys(nodes, 0.0)  # a node's faults never overlap
    down: dict[str, float] = {}  # nodes out of the ring until
    partition_until = 0.0
    ops: list[Operation] = []
    t = 1.0
    while True:
        # mostly spread out, sometimes a burst: several faults at once or during a recovery
        t += rng.uniform(0.0, 0.1) if rng.random() < 0.35 else rng.expovariate(1 / 1.2)
        if t >= last_end - 0.3:
            break
        kind = rng.choice(list(kinds))
        at = round(t, 3)
        if kind == "partition":
            length = rng.uniform(0.5, 2.0)
            if partition_until > at or at + length > last_end:
                continue
            shuffled = list(nodes)
            rng.shuffle(shuffled)
            cut = rng.randrange(1, len(shuffled))
            groups = [sorted(shuffled[:cut], key=nodes.index), sorted(shuffled[cut:], key=nodes.index)]
            value = "|".join(",".join(g) for g in groups)
            ops.append(
                Operation(
                    (
                        {"at": at, "node": "all", "kind": "partition", "value": value},
                        {"at": round(at + length, 3), "node": "all", "kind": "heal"},
                    )
                )
            )
            partition_until = at + length + 0.2
            continue
        free = [n for n in nodes if busy[n] <= at]
        if not free:
            continue
        node = rng.choice(free)
        removes = kind in ("crash", "crashloop", "hang", "softhang", "leave")
        if removes and sum(1 for until in down.values() if until > at) >= MAX_DOWN:
            continue
        steps: list[dict[str, Any]]
        if kind in ("crash", "crashloop"):
            times = [at] if kind == "crash" else [at + i * RESPAWN_S for i in range(rng.randint(2, 3))]
            if times[-1] + RESPAWN_S > last_end:
                continue
            steps = [{"at": round(x, 3), "node": node, "kind": "crash"} for x in times]
            end = times[-1] + RESPAWN_S
        elif kind == "lose":
            steps = [{"at": at, "node": node, "kind": "lose", "count": rng.randint(1, 2)}]
            end = at + 0.1
        else:
            length = rng.uniform(0.2, 1.5)
            end = at + length
            if end > last_end:
                continue
            first: dict[str, Any] = {"at": at, "node": node}
            closing = "clear"
            if kind in ("hang", "softhang"):
                first["kind"] = "hang"
                if kind == "softhang":
                    first["soft"] = True
                closing = "resume"
            elif kind == "leave":
                first["kind"] = "leave"
                closing = "join"
            elif kind == "delay":
                first.update(kind="delay", value=rng.randint(1, 5), jitter=rng.randint(0, 2))
            elif kind in ("drop", "corrupt"):
                first.update(kind=kind, value=round(rng.uniform(0.05, 0.3), 2))
            else:
                first["kind"] = "duplicate"
            steps = [first, {"at": round(end, 3), "node": node, "kind": closing}]
        busy[node] = end + 0.05
        if removes:
            down[node] = end
        ops.append(Operation(tuple(steps)))
    return ops


def scenario_document(
    ops: Sequence[Operation],
    *,
    settle: float = 3.0,
    comment: str = "",
    sim: dict[str, Any] | None = None,
    downloads: bool = False,
) -> str:
    """The operations as a scenario file for ``tokenring chaos`` (every node, respawn, probe);
    ``sim``: how ``tokenring sim`` ran it (seed, bitrate), for its ``--replay``; ``downloads``:
    programs moved all along (virtual time only)."""
    faults = sorted((step for op in ops for step in op.steps), key=lambda s: float(s["at"]))
    doc: dict[str, Any] = {
        "ring": {"nodes": "all", "bitrate": "max", "ack": "adaptive", "respawn": True, "workload": "probe"},
        "settle": settle,
        "faults": faults,
    }
    if downloads:
        doc["ring"]["downloads"] = True
    if sim:
        doc["sim"] = sim
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    return header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=110)


def shrink(
    ops: Sequence[Operation],
    still_fails: Callable[[list[Operation]], bool],
    max_runs: int,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[Operation], int]:
    """Remove operations while ``still_fails`` says the run still fails (ddmin over whole
    operations); at most ``max_runs`` calls. Returns the smallest failing schedule and the
    number of runs."""
    current = list(ops)
    runs = 0
    parts = 2
    while len(current) >= 2 and runs < max_runs:
        size = -(-len(current) // parts)
        reduced = False
        for i in range(0, len(current), size):
            candidate = current[:i] + current[i + size :]
            if not candidate:
                continue
            runs += 1
            if progress:
                progress(f"shrink run {runs}/{max_runs}: {len(candidate)} of {len(current)} operations")
            if still_fails(candidate):
                current = candidate
                parts = max(parts - 1, 2)
                reduced = True
                break
            if runs >= max_runs:
                break
        if not reduced:
            if size == 1:
                break
            parts = min(len(current), parts * 2)
    return current, runs
