"""``tokenring node``: run one node in this process (what ``up`` starts per module)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cliutil import add_ring_options
    from tokenring.nodeproc import add_node_arguments

    p = sub.add_parser(
        "node",
        help="run one node (what `up` starts per module)",
        description="Run one node of the ring in this process until SIGINT/SIGTERM.",
    )
    add_node_arguments(p)
    p.add_argument("--bitrate", default="2.5M", help="emulated ARCNET bitrate or max (default %(default)s)")
    p.add_argument("--ack", default="adaptive", choices=("adaptive", "always", "never"))
    add_ring_options(p)


def run(args: argparse.Namespace) -> int:
    from tokenring.nodeproc import run_node

    return run_node(args)
