"""``tokenring node``: run one node in this process (what ``up`` starts per module)."""

from __future__ import annotations

import argparse

HELP = "run one node (what `up` starts per module)"

EXAMPLES = """examples:
  tokenring node --id 90 --name extra          # a bare node joins the default ring; load gives it a program
  tokenring node --id 90 --program hello.py    # a node running its program from a file, no download
  tokenring node --id 90 --ring lab -e tcp/10.0.0.5:7447 --duration 60
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import add_ring_options, with_examples

    p = sub.add_parser(
        "node",
        help=HELP,
        description="Run one node of the ring in this process until SIGINT/SIGTERM.",
        **with_examples(EXAMPLES),
    )
    add_node_arguments(p)
    p.add_argument("--bitrate", default="2.5M", help="emulated ARCNET bitrate or max (default %(default)s)")
    p.add_argument("--ack", default="adaptive", choices=("adaptive", "always", "never"))
    add_ring_options(p)


def add_node_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of one node process (the launcher passes them to every node)."""
    from tokenring._util.files import LIMITS
    from tokenring.cli.args import int_within, node_id, seconds
    from tokenring.contract import keys
    from tokenring.node.pacing import PROFILES
    from tokenring.node.system.vocabulary import DEFAULT_CAPACITY
    from tokenring.transport.factory import TRANSPORTS

    parser.add_argument("--id", type=node_id, required=True, help="node ID 1..255")
    parser.add_argument(
        "--name",
        type=keys.check_node_name_type,
        help="node name (default: from protocol.yaml, else nodeID); a folder of the program store: "
        "letters, digits, _ - . only",
    )
    parser.add_argument("--program", help="user program file to run on this node (no download)")
    parser.add_argument(
        "--store",
        metavar="DIR",
        help="program store root (battery-backed RAM; default $TOKENRING_STORE or ~/.local/state/tokenring); "
        "the node keeps its program under DIR/<ring>/<name>/",
    )
    parser.add_argument("--no-store", action="store_true", help="keep downloaded programs in memory only")
    parser.add_argument(
        "--capacity",
        type=int_within(1, LIMITS["program file"]),
        default=DEFAULT_CAPACITY,
        metavar="BYTES",
        help=f"largest program this node accepts, 1..{LIMITS['program file']} (default %(default)s, "
        "the 8051's code space)",
    )
    parser.add_argument("--autostart", action="store_true", help="start the stored program at boot")
    parser.add_argument("--duration", type=seconds, help="leave after this many seconds")
    parser.add_argument(
        "--expect",
        type=int_within(1, 255),
        metavar="N",
        help="N nodes (1..255) are booting together (the launcher says so): the first token waits until "
        "all N are live, at most 5 s or 0.5 s per node",
    )
    parser.add_argument(
        "--transport",
        default="zenoh",
        choices=TRANSPORTS,
        help="what carries the token (default %(default)s; udp/zmq need --registry, for comparisons)",
    )
    parser.add_argument(
        "--registry", metavar="HOST:PORT", help="membership registry of the udp/zmq transports"
    )
    parser.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        help="emulate a hardware's timing on top of the wire (arcnet: the seed robot)",
    )
    parser.add_argument(
        "--link-listen",
        metavar="ENDPOINT",
        help="pass the token on a direct link too: listen here in a second session, a Zenoh peer "
        "without gossip (the launcher's --links)",
    )
    parser.add_argument(
        "--link-connect", metavar="ENDPOINT", help="with --link-listen: the ring successor's link endpoint"
    )
    parser.add_argument(
        "--no-resident",
        action="store_true",
        help="no application adds to this node's OS (the launcher asked): load none at boot, "
        "only when a program starts",
    )


def run(args: argparse.Namespace) -> int:
    from tokenring.node.process import run_node

    return run_node(args)
