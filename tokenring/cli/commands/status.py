"""``tokenring status``: membership and counters of a running ring."""

from __future__ import annotations

import argparse
import sys

from tokenring.cli.args import seconds

HELP = "membership and counters of a running ring"

EXAMPLES = """examples:
  tokenring status                             # the default ring, through tcp/127.0.0.1:7447
  tokenring status --ring lab -e tcp/10.0.0.5:7447
  tokenring status --json | jq '.nodes[].successor'
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import add_json_option, add_ring_options, with_examples

    p = sub.add_parser("status", help=HELP, **with_examples(EXAMPLES))
    p.add_argument("--timeout", type=seconds, default=2.0, help="seconds to wait for answers")
    add_json_option(p)
    add_ring_options(p, listen=False)


def program_cell(node: dict) -> str:
    """A node's program and, unless it simply runs, its state: ``Probe (SETTING_UP 12 s)``."""
    name = node.get("program")
    if not name:
        return "-"
    state = node.get("program_state")
    if state == "setting up":
        return f"{name} (SETTING_UP {node.get('setup_s') or 0:.0f} s)"
    if state in ("failed", "stopped"):
        return f"{name} ({state.upper()})"
    return str(name)


def setup_warnings(nodes: list[dict]) -> list[str]:
    """A line for every program whose setup() has not returned after SETUP_WARNING_S."""
    from tokenring.node.program_host import SETUP_WARNING_S

    return [
        f"{n['name']} ({n['id']}): setup() of {n['program']} has not returned after {n['setup_s']:.0f} s; "
        "its run() has not started"
        for n in nodes
        if n.get("program_state") == "setting up" and (n.get("setup_s") or 0) >= SETUP_WARNING_S
    ]


def run(args: argparse.Namespace) -> int:
    from tokenring._util.tables import format_table
    from tokenring.cli.args import tap_session
    from tokenring.cli.output import print_json
    from tokenring.contract import keys
    from tokenring.host.regeneration import format_rates, ring_rates
    from tokenring.transport.session import discover, query

    with tap_session(args) as session:
        discover(session, args.ring, timeout=args.timeout + 3.0)
        replies = query(session, keys.control(args.ring, "*", "stats"), timeout=args.timeout)
    nodes = sorted((r["result"] for _, r in replies if r.get("ok")), key=lambda n: n["id"])
    rates = ring_rates(nodes)
    if args.json:
        print_json({"ring": args.ring, "regenerations": rates, "nodes": nodes})
        return 0 if nodes else 1
    if not nodes:
        print(f"no node of ring {args.ring!r} answered", file=sys.stderr)
        return 1
    rows = [
        [
            n["id"],
            n["name"],
            n["successor"],
            n["counter"],
            f"{n['round_ms']['median']:.3f}",
            f"{n['round_ms']['p99']:.3f}",
            f"{n['handler_us']['median']:.1f}",
            f"{n['send_us']['median']:.0f}",
            n["stats"]["rejected_crc"],
            n["stats"]["reconfigurations"],
            n["stats"]["tokens_regenerated"],
            n["regenerations"]["spurious"] if "regenerations" in n else "?",
            program_cell(n),
        ]
        for n in nodes
    ]
    print(
        format_table(
            rows,
            [
                "id",
                "name",
                "next",
                "counter",
                "rtt ms",
                "p99 ms",
                "handler us",
                "put us",
                "crc rej",
                "reconf",
                "regen",
                "spurious",
                "program",
            ],
        )
    )
    print(format_rates(rates))
    for line in setup_warnings(nodes):
        print(f"warning: {line}", file=sys.stderr)
    return 0
