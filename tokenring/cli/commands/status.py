"""``tokenring status``: membership and counters of a running ring."""

from __future__ import annotations

import argparse
import sys
import threading
from typing import TYPE_CHECKING

from tokenring.cli.args import seconds

if TYPE_CHECKING:
    import zenoh

HELP = "membership and counters of a running ring"

EXAMPLES = """examples:
  tokenring status                             # the default ring, through tcp/127.0.0.1:7447
  tokenring status --ring lab -e tcp/10.0.0.5:7447
  tokenring status --json | jq '.nodes[].successor'
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import add_json_option, add_ring_options, with_examples

    p = sub.add_parser(
        "status",
        help=HELP,
        description="Every node's membership, round trip and counters, and the ring's regenerations "
        "by cause. Exit 0 when nodes answered, 1 when none did. When the endpoint answers nothing, "
        "status says what holds it on this host; a launcher stopped there (SIGSTOP, Ctrl-Z) still "
        "has live nodes, and they are asked directly (exit 0, a line on stderr says so), unless it "
        "is their router (up --router).",
        **with_examples(EXAMPLES),
    )
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


def ask_nodes(session: zenoh.Session, args: argparse.Namespace) -> list[dict]:
    """Every node's ``stats``, by ID, once the session sees the ring's nodes settle."""
    from tokenring.contract import keys
    from tokenring.transport.session import discover, query

    discover(session, args.ring, timeout=args.timeout + 3.0)
    replies = query(session, keys.control(args.ring, "*", "stats"), timeout=args.timeout)
    return sorted((r["result"] for _, r in replies if r.get("ok")), key=lambda n: n["id"])


def past_the_endpoint(args: argparse.Namespace) -> tuple[list[dict], str | None]:
    """When the endpoint answered nothing: the nodes asked directly if a stopped launcher holds
    it on this host (they go on without it), and a line saying what holds it; no nodes and
    None when there is nothing to look at (an endpoint on another host)."""
    from tokenring.contract import keys
    from tokenring.transport.reach import diagnose
    from tokenring.transport.zenoh_config import make_config, open_session

    endpoint = (args.connect or [keys.default_endpoint()])[0]
    silence = diagnose(endpoint)
    if silence is None:
        return [], None
    if not (silence.stopped and silence.node_endpoints):
        return [], silence.describe()
    # no gossip: it would link this session to the stopped launcher too, whose handshake never ends
    config = make_config(connect=silence.node_endpoints, config_file=args.zenoh_config, gossip=False)
    with open_session(config) as direct:
        nodes = ask_nodes(direct, args)
    if not nodes:
        return [], silence.describe()
    return nodes, (
        f"{silence.who} holds {endpoint} but is stopped (SIGSTOP or Ctrl-Z), so its {len(nodes)} "
        f"node(s) were asked directly; resume it with: kill -CONT {silence.pid}"
    )


def run(args: argparse.Namespace) -> int:
    from tokenring._util.tables import format_table
    from tokenring.cli.args import tap_session
    from tokenring.cli.output import print_json
    from tokenring.host.regeneration import format_rates, ring_rates
    from tokenring.transport.reach import answered

    session = tap_session(args)
    linked = False
    try:
        linked = answered(session, wait=args.timeout)
        nodes = ask_nodes(session, args) if linked else []
    finally:
        if linked:
            session.close()
        else:  # a session shaking hands with a stopped peer takes Zenoh's handshake timeout to close
            threading.Thread(target=session.close, name="close-unanswered", daemon=True).start()
    note = None
    if not linked:  # nobody answered at the endpoint: say who holds it, and go past a stopped launcher
        nodes, note = past_the_endpoint(args)
    rates = ring_rates(nodes)
    if note is not None:
        print(f"status: {note}", file=sys.stderr)
    if args.json:
        print_json({"ring": args.ring, "regenerations": rates, "nodes": nodes, "note": note})
        return 0 if nodes else 1
    if not nodes:
        if note is None:
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
