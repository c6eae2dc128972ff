"""``tokenring fault``: inject a fault into one node (or ``all``) of a running ring."""

from __future__ import annotations

import argparse
import sys
import time
from typing import TYPE_CHECKING, Any

from tokenring.cli.args import add_ring_options, int_within, number_within, seconds
from tokenring.errors import UsageError

if TYPE_CHECKING:
    import zenoh

HELP = "inject a fault into a node of a running ring (crash, hang, delay, drop, ...)"

EXAMPLES = """examples:
  tokenring fault sonar crash                  # the sonar's process exits at once (code 70)
  tokenring fault motor delay 5 --jitter 2     # every token waits 5 ± 2 ms at the motor
  tokenring fault lcd drop 0.1                 # one token in ten lost at the LCD
  tokenring fault all partition 'main,motor|sonar,compass'
  tokenring fault all heal                     # end the partition
  tokenring fault all clear                    # end every fault on every node
  tokenring fault --list                       # the active faults of every node
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import with_examples
    from tokenring.contract.faults import KINDS, MAX_DELAY_MS, MAX_LOSE

    p = sub.add_parser(
        "fault",
        help=HELP,
        description="Inject a fault into one node of a running ring, through its control key "
        "tokenring/<ring>/ctl/<ID>/fault. Kinds: " + ", ".join(KINDS) + ".",
        **with_examples(EXAMPLES),
    )
    p.add_argument("node", nargs="?", help="node name or ID, or 'all'")
    p.add_argument("kind", nargs="?", choices=KINDS, metavar="KIND", help="fault kind: " + ", ".join(KINDS))
    p.add_argument(
        "value",
        nargs="?",
        help=f"delay: ms 0..{MAX_DELAY_MS}; drop/corrupt: probability 0..1; partition: A,B|C,D",
    )
    p.add_argument(
        "--jitter",
        type=number_within(0, MAX_DELAY_MS, "ms"),
        default=0.0,
        metavar="MS",
        help=f"delay jitter (± ms, 0..{MAX_DELAY_MS})",
    )
    p.add_argument(
        "--count",
        type=int_within(1, MAX_LOSE),
        default=1,
        metavar="N",
        help=f"lose: how many tokens (1..{MAX_LOSE})",
    )
    p.add_argument("--soft", action="store_true", help="hang: freeze the node OS only (across hosts)")
    p.add_argument("--list", action="store_true", help="show the active faults of every node")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--timeout", type=seconds, default=2.0, help="seconds to wait for answers")
    add_ring_options(p, listen=False)


def live_nodes(session: zenoh.Session, ring: str, timeout: float) -> dict[int, str]:
    """ID → name of every live node of the ring — also a hung one that answers nothing but
    still holds its liveliness token (it must stay reachable for ``resume``)."""
    from tokenring.contract import keys
    from tokenring.contract.protocol import default_protocol
    from tokenring.transport.session import discover, query

    expected = discover(session, ring, timeout=timeout + 3.0)
    found: dict[int, str] = {}
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for _, reply in query(session, keys.control(ring, "*", "stats"), timeout=min(1.0, timeout)):
            if reply.get("ok"):
                found[reply["result"]["id"]] = reply["result"]["name"]
        if found and expected <= set(found):
            break
    protocol = default_protocol()
    for node_id in expected - set(found):
        spec = protocol.by_id.get(node_id)
        found[node_id] = spec.name if spec else f"node{node_id}"
    return found


def resolver(nodes: dict[int, str], which: str = "live") -> Any:
    """A function from a node's name or ID to its ID, refusing one not in ``nodes``."""

    def resolve(item: str) -> int:
        for node_id, name in nodes.items():
            if item == name or item == str(node_id):
                return node_id
        known = ", ".join(f"{n}={i}" for i, n in sorted(nodes.items()))
        raise UsageError(f"unknown node {item!r} ({which}: {known or 'none'})")

    return resolve


def build_request(args: argparse.Namespace, resolve) -> dict[str, Any]:
    from tokenring.contract.faults import NEEDS_VALUE, parse_partition, parse_probability, validate

    kind = args.kind
    if kind in NEEDS_VALUE and args.value is None:
        raise UsageError(f"{kind} needs a value: {kind} {NEEDS_VALUE[kind]}")
    if kind not in NEEDS_VALUE and args.value is not None:
        raise UsageError(f"{kind} takes no value (got {args.value!r})")
    request: dict[str, Any] = {"kind": kind}
    if kind == "delay":
        request["ms"] = args.value  # validate() checks it: a finite number of ms within range
        request["jitter_ms"] = args.jitter
    elif kind in ("drop", "corrupt"):
        request["p"] = parse_probability(args.value, kind)
    elif kind == "partition":
        request["groups"] = parse_partition(args.value, resolve)
    elif kind == "lose":
        request["count"] = args.count
    elif kind == "hang":
        request["soft"] = args.soft
    return validate(request)


def run(args: argparse.Namespace) -> int:
    from tokenring.cli.args import tap_session
    from tokenring.cli.output import print_json
    from tokenring.contract import keys
    from tokenring.contract.protocol import default_protocol, load_protocol
    from tokenring.host.faults import FaultClient
    from tokenring.transport.zenoh_config import unanswered_hint

    ring = keys.check_ring_name(args.ring)
    if not args.list and (args.node is None or args.kind is None):
        raise UsageError("give a node and a fault kind (e.g. 'fault sonar crash'), or --list")
    if not args.list:
        # names and values that protocol.yaml alone can refuse are refused before any waiting
        known = {spec.id: spec.name for spec in load_protocol(args.protocol).nodes.values()}
        if args.node != "all":
            resolver(known, "in protocol.yaml")(args.node)
        build_request(args, resolver(known, "in protocol.yaml"))
    with tap_session(args) as session:
        nodes = live_nodes(session, ring, args.timeout)
        if not nodes:
            raise UsageError(
                f"no node of ring {ring!r} answered (is it running, and is --ring right{unanswered_hint()}?)"
            )
        if args.kind == "resume":
            # a SIGSTOPped node answers nothing and a fresh session cannot even see it: take
            # every node protocol.yaml knows (the launcher resolves the process)
            for spec in default_protocol().nodes.values():
                nodes.setdefault(spec.id, spec.name)
        resolve = resolver(nodes)
        if args.list:
            return show_list(session, ring, nodes, args)
        targets = sorted(nodes) if args.node == "all" else [resolve(args.node)]
        request = build_request(args, resolve)
        client = FaultClient(session, ring, args.timeout)
        results = [client.inject(node_id, request) for node_id in targets]
    if args.json:
        print_json({"ring": ring, "request": request, "results": results})
    else:
        for result in results:
            faults = ", ".join(sorted(result.get("faults", {}))) or "none"
            print(f"{result.get('node')} ({result.get('id')}): {request['kind']} -> active faults: {faults}")
    return 0


def show_list(session: zenoh.Session, ring: str, nodes: dict[int, str], args: argparse.Namespace) -> int:
    from tokenring._util.tables import format_table
    from tokenring.cli.output import print_json
    from tokenring.contract import keys
    from tokenring.transport.session import query

    rows = []
    listing = []
    for node_id, name in sorted(nodes.items()):
        answer = query(session, keys.control(ring, node_id, "fault"), {"kind": "list"}, timeout=args.timeout)
        if not answer or not answer[0][1].get("ok"):
            listing.append({"id": node_id, "node": name, "faults": None})
            rows.append([node_id, name, "(no answer: hung?)", ""])
            continue
        result = answer[0][1]["result"]
        listing.append(result)
        for kind, spec in sorted(result["faults"].items()) or [("-", {})]:
            options = ", ".join(f"{k}={v}" for k, v in spec.items() if k not in ("kind", "since"))
            since = time.strftime("%H:%M:%S", time.localtime(spec["since"])) if "since" in spec else ""
            rows.append([node_id, name, kind + (f" ({options})" if options else ""), since])
    if args.json:
        print_json({"ring": ring, "nodes": listing})
    else:
        sys.stdout.write(format_table(rows, ["id", "node", "fault", "since"]) + "\n")
    return 0
