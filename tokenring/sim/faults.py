"""Faults in virtual time (``tokenring sim --fault KIND[:NODE[:VALUE]]@T``, issue 55).

Every kind of ``tokenring fault`` applied to the simulated ring at a virtual instant, by the same
code that applies it to a real node where the fault acts inside the node: the node's own
:class:`~tokenring.node.faults.FaultInjector` (``delay``, ``drop``, ``corrupt``, ``duplicate``,
``lose``, ``partition``, ``heal``, ``leave``, ``join``, ``clear``), whose random draws come from the
simulation's seed. Where the real one acts on the process, the memory hub stands in for it:
``crash`` makes the node vanish (:meth:`MemoryHub.crash`, its watchdog stilled like a dead
process's), ``hang`` stops it like SIGSTOP (deliveries, sends and its watchdog stand still:
:meth:`MemoryHub.freeze` and ``paused``), ``resume`` thaws it, as the launcher's SIGCONT does.
As on real processes, ``clear`` does not reach a hung node (only ``resume`` does).

After each fault the scenario watches, on the virtual clock, for the ring circulating again:
every working node (neither crashed nor hung) visited :data:`VISITS_AGAIN` times since the fault
and every crashed or hung one out of their rings. That instant, less the fault's, is the fault's
``recovered_s``; the regenerations in between are its ``regenerations``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from tokenring.contract.faults import KINDS, MAX_LOSE, NEEDS_VALUE, parse_partition, validate
from tokenring.errors import UsageError

if TYPE_CHECKING:
    from tokenring.contract.protocol import Protocol
    from tokenring.runtime import SimRuntime
    from tokenring.sim.ring import SimRing

#: visits of every working node after a fault that count as the ring circulating again
VISITS_AGAIN = 3
#: how often (virtual seconds) a fault not yet recovered from is looked at: the figure's grain
POLL_S = 0.001
#: kinds the hub applies (the real ones act on the node's process)
PROCESS_KINDS = frozenset({"crash", "hang", "resume"})


@dataclass(frozen=True)
class FaultAt:
    """One ``--fault``: a request (as ``tokenring fault`` sends it) for ``nodes`` at ``at_s``."""

    at_s: float
    kind: str
    nodes: tuple[int, ...]
    request: dict[str, Any]
    text: str


def parse_fault(text: str, protocol: Protocol, ids: list[int]) -> FaultAt:
    """``KIND[:NODE[:VALUE]]@T`` → a :class:`FaultAt` (NODE: a name, an ID or ``all``, the
    default; VALUE as ``tokenring fault`` takes it: delay MS, drop/corrupt/duplicate P, lose
    COUNT, partition ``A,B|C,D``). Raises :class:`UsageError` naming ``--fault``."""
    where = f"--fault {text!r}"
    body, at, when = text.rpartition("@")
    if not at or not body:
        raise UsageError(
            f"{where}: expected KIND[:NODE[:VALUE]]@T (T in simulated seconds), e.g. drop:30:0.5@2"
        )
    try:
        at_s = float(when)
    except ValueError:
        raise UsageError(f"{where}: the time {when!r} is not a number of simulated seconds") from None
    if not (math.isfinite(at_s) and at_s >= 0):
        raise UsageError(f"{where}: the time {when!r} is not a number of simulated seconds >= 0")
    kind, _, rest = body.partition(":")
    node, _, value = rest.partition(":")
    if kind not in KINDS or kind == "list":
        raise UsageError(
            f"{where}: unknown fault kind {kind!r} (kinds: {', '.join(k for k in KINDS if k != 'list')})"
        )

    def resolve(item: str) -> int:
        try:
            node_id = protocol.node(item.strip()).id
        except Exception:
            node_id = None
        if node_id not in ids:
            raise UsageError(f"{where}: {item!r} is not a node of this ring ({','.join(map(str, ids))})")
        return node_id

    nodes = tuple(ids) if node in ("", "all") else (resolve(node),)
    if kind in NEEDS_VALUE and not value:
        raise UsageError(f"{where}: {kind} needs a value: {kind}:NODE:{NEEDS_VALUE[kind]}@T")
    if value and kind not in (*NEEDS_VALUE, "duplicate", "lose"):
        raise UsageError(f"{where}: {kind} takes no value (got {value!r})")
    request: dict[str, Any] = {"kind": kind}
    try:
        if kind == "delay":
            request["ms"] = value
        elif kind in ("drop", "corrupt", "duplicate") and value:
            request["p"] = value
        elif kind == "lose" and value:
            if not value.isdigit():
                raise UsageError(f"lose: count {value!r} is not a whole number within 1..{MAX_LOSE}")
            request["count"] = int(value)
        elif kind == "partition":
            request["groups"] = parse_partition(value, resolve)
        elif kind == "hang":
            request["soft"] = False
        request = validate(request)
    except UsageError as exc:
        raise UsageError(f"{where}: {exc}") from None
    return FaultAt(at_s, kind, nodes, request, text)


def fault_scenario(
    faults: list[FaultAt], duration_s: float
) -> Callable[[SimRuntime, SimRing], dict[str, Any]]:
    """A scenario for :func:`tokenring.sim.run_ring`: the faults at their instants, the ring
    watched for recovery after each, ``duration_s`` of virtual time in all."""
    late = [f.text for f in faults if f.at_s > duration_s]
    if late:
        raise UsageError(f"--fault {late[0]!r}: after the run's end (--duration {duration_s:g})")
    schedule = sorted(faults, key=lambda f: f.at_s)  # stable: the command line's order at one instant

    def scenario(sim: SimRuntime, ring: SimRing) -> dict[str, Any]:
        crashed: set[int] = set()
        hung: set[int] = set()
        applied: list[dict[str, Any]] = []
        watching: list[tuple[dict[str, Any], dict[int, int], int]] = []  # (record, visits then, regens then)

        def regenerations() -> int:
            return sum(n.stats.tokens_regenerated for n in ring.nodes.values())

        def circulating(visits: dict[int, int]) -> bool:
            working = [i for i in ring.nodes if i not in crashed and i not in hung]
            away = crashed | hung
            return bool(working) and all(
                ring.nodes[i].stats.visits >= visits.get(i, 0) + VISITS_AGAIN
                and not away & set(ring.nodes[i].membership.active)
                for i in working
            )

        def look() -> None:
            for entry in list(watching):
                record, visits, regens = entry
                if circulating(visits):
                    record["recovered_s"] = round(sim.now - record["at_s"], 6)
                    record["regenerations"] = regenerations() - regens
                    watching.remove(entry)

        def apply(fault: FaultAt) -> None:
            record: dict[str, Any] = {
                "at_s": round(sim.now, 6),
                "fault": fault.text,
                "request": fault.request,
                "nodes": list(fault.nodes),
                "skipped": [],
                "recovered_s": None,
                "regenerations": None,
            }
            for node_id in fault.nodes:
                node = ring.nodes[node_id]
                if node_id in crashed:
                    record["skipped"].append(node_id)  # a crashed node answers nothing, ever
                elif fault.kind == "crash":
                    crashed.add(node_id)
                    hung.discard(node_id)
                    node.paused = True  # a dead process's watchdog regenerates nothing
                    ring.hub.crash(node_id)
                elif fault.kind == "hang":
                    if node_id not in hung:
                        hung.add(node_id)
                        node.paused = True
                        ring.hub.freeze(node_id)
                elif fault.kind == "resume":
                    if node_id in hung:
                        hung.discard(node_id)
                        node.paused = False
                        ring.hub.freeze(node_id, False)
                    ring.faults[node_id].handle(fault.request)  # ends a soft hang too
                elif node_id in hung:
                    record["skipped"].append(node_id)  # a stopped process hears no request
                else:
                    ring.faults[node_id].handle(fault.request)
            applied.append(record)
            watching.append((record, {i: n.stats.visits for i, n in ring.nodes.items()}, regenerations()))

        for fault in schedule:
            while sim.now < fault.at_s:
                sim.sleep(min(POLL_S, fault.at_s - sim.now) if watching else fault.at_s - sim.now)
                look()
            apply(fault)
        while sim.now < duration_s:
            sim.sleep(min(POLL_S, duration_s - sim.now) if watching else duration_s - sim.now)
            look()
        counts: dict[str, dict[str, int]] = {}
        for node_id, injector in ring.faults.items():
            done = {k: v for k, v in injector.counts.items() if v}
            if done:
                counts[str(node_id)] = done
        return {"faults": applied, "fault_counts": counts, "crashed": sorted(crashed), "hung": sorted(hung)}

    return scenario
