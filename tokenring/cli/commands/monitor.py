"""``tokenring monitor``: a live terminal view of a running ring.

Membership and the successor chain, the round-trip time, per-node counters like the Linux
arcnet driver's (reconfigurations, successor changes, unacknowledged passes, CRC rejects,
inbox-full refusals, regenerations, stale tokens dropped), the faults active on each node, and
an event log where fault periods, membership changes and reconfigurations are marked. The
ring's regenerations per hour, and the spurious ones among them (no fault on any node and no
node come or gone in the seconds before: tokenring/node/regeneration.py), head the view.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from typing import Any

from tokenring.cli.args import add_ring_options, positive_int, seconds

HELP = "live terminal view of a running ring"

EXAMPLES = """examples:
  tokenring monitor                            # refreshes twice a second until Ctrl-C
  tokenring monitor --once                     # one snapshot, then exit
  tokenring monitor --json --interval 5 --count 12 > minute.jsonl
"""

COUNTERS = (
    ("reconfigurations", "reconf"),
    ("successor_changes", "succ chg"),
    ("unacked_passes", "unacked"),
    ("rejected_crc", "crc rej"),
    ("inbox_full", "inbox full"),
    ("tokens_regenerated", "regen"),
    ("stale_tokens", "stale"),
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import with_examples

    p = sub.add_parser("monitor", help=HELP, description=__doc__, **with_examples(EXAMPLES))
    p.add_argument("--interval", type=seconds, default=0.5, help="seconds between refreshes")
    p.add_argument("--once", action="store_true", help="print one snapshot and exit")
    p.add_argument("--count", type=positive_int, help="stop after this many refreshes")
    p.add_argument("--json", action="store_true", help="one JSON object per refresh")
    add_ring_options(p, listen=False)


def snapshot(session: Any, ring: str) -> dict[str, Any]:
    from tokenring.contract import keys
    from tokenring.host.regeneration import ring_rates
    from tokenring.transport.session import query

    nodes = {}
    for _, reply in query(session, keys.control(ring, "*", "stats"), timeout=1.0):
        if reply.get("ok"):
            nodes[reply["result"]["id"]] = reply["result"]
    faults = {}
    for _, reply in query(session, keys.control(ring, "*", "fault"), {"kind": "list"}, timeout=1.0):
        if reply.get("ok"):
            faults[reply["result"]["id"]] = reply["result"]["faults"]
    return {"t": time.time(), "nodes": nodes, "faults": faults, "regenerations": ring_rates(nodes.values())}


def spurious(node: dict[str, Any]) -> int | None:
    """The node's spurious regenerations (None from a node that does not count them)."""
    ledger = node.get("regenerations")
    return None if ledger is None else int(ledger["spurious"])


def diff_events(previous: dict[str, Any] | None, current: dict[str, Any]) -> list[str]:
    """What changed between two snapshots, as event lines (fault periods, membership, counters)."""
    if previous is None:
        return []
    events = []
    before, after = previous["nodes"], current["nodes"]
    names = {i: n["name"] for i, n in {**before, **after}.items()}
    for node_id in sorted(set(before) - set(after)):
        events.append(f"{names[node_id]} ({node_id}) stopped answering")
    for node_id in sorted(set(after) - set(before)):
        events.append(f"{names[node_id]} ({node_id}) joined")
    for node_id in sorted(set(before) & set(after)):
        old, new = before[node_id], after[node_id]
        if old["successor"] != new["successor"]:
            events.append(f"{names[node_id]}: successor {old['successor']} -> {new['successor']}")
        for key, label in COUNTERS:
            grown = new["stats"].get(key, 0) - old["stats"].get(key, 0)
            if grown > 0 and key not in ("successor_changes",):
                note = ""
                if key == "tokens_regenerated":
                    more = (spurious(new) or 0) - (spurious(old) or 0)
                    note = f" (SPURIOUS +{more})" if more > 0 else ""
                events.append(f"{names[node_id]}: {label} +{grown}{note}")
    old_faults, new_faults = previous["faults"], current["faults"]
    for node_id in sorted(set(old_faults) | set(new_faults)):
        old_set, new_set = set(old_faults.get(node_id) or {}), set(new_faults.get(node_id) or {})
        for kind in sorted(new_set - old_set):
            events.append(f"FAULT START {names.get(node_id, node_id)}: {kind}")
        for kind in sorted(old_set - new_set):
            events.append(f"FAULT END   {names.get(node_id, node_id)}: {kind}")
    return events


def header_lines(ring: str, snap: dict[str, Any]) -> list[str]:
    """The view's head: who answers, the round trip, the successor chain, regeneration rates."""
    from tokenring.host.regeneration import format_rates, ring_rates

    nodes = snap["nodes"]
    lines = [
        f"tokenring monitor - ring {ring!r} - {time.strftime('%H:%M:%S')} - {len(nodes)} nodes answering"
    ]
    if nodes:
        master = min(nodes.values(), key=lambda n: n["id"])
        round_ms = master["round_ms"]
        lines.append(
            f"round trip at {master['name']}: median {round_ms['median']:.3f} ms, p99 {round_ms['p99']:.3f} ms;"
            f" epoch {master['epoch'][0]}/{master['epoch'][1]}, counter {master['counter']}"
        )
        chain, seen, current = [], set(), master["id"]
        while current in nodes and current not in seen:
            seen.add(current)
            chain.append(f"{nodes[current]['name']}({current})")
            current = nodes[current]["successor"]
        chain.append(f"{nodes[current]['name']}({current})" if current in nodes else f"?({current})")
        lines.append("ring: " + " -> ".join(chain))
        lines.append(format_rates(snap.get("regenerations") or ring_rates(nodes.values())))
    return lines


HEADERS = [
    "id",
    "name",
    "next",
    "counter",
    "round ms",
    "handler us",
    *[label for _, label in COUNTERS],
    "spurious",
    "faults",
]


def table_rows(snap: dict[str, Any]) -> list[list[Any]]:
    """One row per answering node, in the order of :data:`HEADERS`."""
    rows = []
    for node_id, n in sorted(snap["nodes"].items()):
        faults = snap["faults"].get(node_id)
        rows.append(
            [
                node_id,
                n["name"],
                n["successor"],
                n["counter"],
                f"{n['round_ms']['median']:.2f}",
                f"{n['handler_us']['median']:.0f}",
                *[n["stats"].get(key, 0) for key, _ in COUNTERS],
                "?" if spurious(n) is None else spurious(n),
                ",".join(sorted(faults)) if faults else "-",
            ]
        )
    return rows


def excluded_ids(snap: dict[str, Any]) -> set[int]:
    """Nodes some answering node has excluded from the ring (they may still answer)."""
    return {int(i) for n in snap["nodes"].values() for i in n.get("excluded") or ()}


def event_stamp(t: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int(t * 1000) % 1000:03d}"


def render(ring: str, snap: dict[str, Any], events: list[tuple[float, str]]) -> str:
    """The view as plain text (a pipe, a file, ``--once``)."""
    from tokenring._util.tables import format_table

    lines = header_lines(ring, snap)
    lines.append(format_table(table_rows(snap), HEADERS))
    lines.append("")
    lines.append("events:")
    for t, text in events[-12:]:
        marker = ">>" if text.startswith("FAULT") else "  "
        lines.append(f" {marker} {event_stamp(t)}  {text}")
    return "\n".join(lines)


#: an event line's colour by what it says (the first match wins)
EVENT_STYLES = (
    ("FAULT START", "bold red"),
    ("FAULT END", "green"),
    ("SPURIOUS", "bold red"),
    ("stopped answering", "red"),
    ("joined", "green"),
    ("regen", "yellow"),
)


def render_rich(ring: str, snap: dict[str, Any], events: list[tuple[float, str]]) -> Any:
    """The view as a ``rich`` renderable for a terminal: active faults and excluded nodes in red,
    regenerations and growing error counters in yellow, spurious regenerations in bold red."""
    from rich.console import Group
    from rich.table import Table
    from rich.text import Text

    from tokenring.host.regeneration import ring_rates

    head = header_lines(ring, snap)
    parts: list[Any] = [Text(head[0], style="bold")]
    rates = snap.get("regenerations") or ring_rates(snap["nodes"].values())
    for line in head[1:]:
        style = ""
        if line.startswith("regenerations:"):
            style = "bold red" if rates["spurious"] else "yellow" if rates["regenerated"] else ""
        parts.append(Text(line, style=style))
    excluded = excluded_ids(snap)
    if excluded:
        parts.append(Text("excluded: " + ", ".join(str(i) for i in sorted(excluded)), style="bold red"))
    table = Table(box=None, padding=(0, 1), header_style="bold")
    counters = {label for _, label in COUNTERS}
    for header in HEADERS:
        table.add_column(header, justify="left" if header in ("name", "faults") else "right")
    for row in table_rows(snap):
        cells = []
        for header, value in zip(HEADERS, row, strict=True):
            alarm = (header == "faults" and value != "-") or (header == "spurious" and value not in (0, "?"))
            warn = header in counters and header != "succ chg" and bool(value)
            style = "bold red" if alarm else "yellow" if warn else ""
            cells.append(Text(str(value), style=style))
        table.add_row(*cells, style="red" if row[0] in excluded else None)
    parts += [table, Text(""), Text("events:")]
    for t, text in events[-12:]:
        style = next((s for key, s in EVENT_STYLES if key in text), "")
        marker = ">>" if text.startswith("FAULT") else "  "
        parts.append(Text(f" {marker} {event_stamp(t)}  {text}", style=style))
    return Group(*parts)


def run(args: argparse.Namespace) -> int:
    import json

    from tokenring.cli.args import tap_session
    from tokenring.contract import keys
    from tokenring.transport.session import discover

    ring = keys.check_ring_name(args.ring)
    events: list[tuple[float, str]] = []
    previous = None
    refreshes = 0
    # a terminal gets a view redrawn in place, in colour; a pipe or a file plain snapshots
    interactive = sys.stdout.isatty() and not args.json
    live = None
    with tap_session(args) as session, contextlib.ExitStack() as stack:
        discover(session, ring, timeout=5.0)
        if interactive:
            from rich.console import Console
            from rich.live import Live

            console = Console()
            if not args.once:
                live = stack.enter_context(Live(console=console, auto_refresh=False, transient=False))
        try:
            while True:
                snap = snapshot(session, ring)
                events += [(snap["t"], e) for e in diff_events(previous, snap)]
                previous = snap
                refreshes += 1
                if args.json:
                    print(
                        json.dumps({**snap, "events": [e for t, e in events if t == snap["t"]]}, default=str),
                        flush=True,
                    )
                elif live is not None:
                    live.update(render_rich(ring, snap, events), refresh=True)
                elif interactive:
                    console.print(render_rich(ring, snap, events))
                else:
                    sys.stdout.write(render(ring, snap, events) + "\n")
                    sys.stdout.flush()
                if args.once or (args.count and refreshes >= args.count):
                    break
                time.sleep(args.interval)
        except KeyboardInterrupt:
            return 130
    return 0 if previous and previous["nodes"] else 1
