"""Ring-wide regeneration rates from the nodes' ledgers (:mod:`tokenring.node.regeneration`),
for ``status``, ``monitor`` and the benchmarks."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from tokenring.node.regeneration import per_hour


def ring_rates(nodes: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """Ring-wide figures from the nodes' ``stats`` replies: regenerations (seeds left out) and
    spurious ones, in total and per hour of the ring's uptime (its longest-running node's).

    A node without a ledger (an older version) adds its ``tokens_regenerated`` to the total; the
    spurious count then covers the nodes that have one (``nodes_counted``)."""
    nodes = list(nodes)
    uptime = 0.0
    regenerated = spurious = fault = membership = network = counted = 0
    for n in nodes:
        ledger = n.get("regenerations")
        if ledger is None:
            regenerated += int(n.get("stats", {}).get("tokens_regenerated", 0))
            continue
        counted += 1
        uptime = max(uptime, float(ledger.get("uptime_s", 0.0)))
        regenerated += int(ledger["regenerated"])
        spurious += int(ledger["spurious"])
        fault += int(ledger["fault"])
        membership += int(ledger["membership"])
        network += int(ledger.get("network", 0))  # a stalled router (older ledgers: none)
    return {
        "uptime_s": uptime,
        "regenerated": regenerated,
        "fault": fault,
        "membership": membership,
        "network": network,
        "spurious": spurious,
        "per_hour": per_hour(regenerated, uptime),
        "spurious_per_hour": per_hour(spurious, uptime),
        "nodes": len(nodes),
        "nodes_counted": counted,
    }


def format_rates(rates: dict[str, Any]) -> str:
    """One line for ``status`` and ``monitor``: regenerations and spurious ones per hour."""

    def rate(value: float | None) -> str:
        return "-" if value is None else f"{value:.1f}/h"

    hours = rates["uptime_s"] / 3600.0
    span = f"{rates['uptime_s'] / 60:.1f} min" if hours < 1 else f"{hours:.2f} h"
    text = (
        f"regenerations: {rates['regenerated']} in {span} ({rate(rates['per_hour'])}); "
        f"spurious (no fault, no membership change): {rates['spurious']} ({rate(rates['spurious_per_hour'])})"
    )
    if rates.get("network"):
        text += f"; the network's (a stalled router): {rates['network']}"
    if rates["nodes_counted"] < rates["nodes"]:
        text += f" - {rates['nodes'] - rates['nodes_counted']} node(s) do not count causes"
    return text
