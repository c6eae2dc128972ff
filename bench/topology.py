"""Bare Zenoh rings of one size in three topologies, alternated: through a router (what
``tokenring up --router`` and ``bench --topology router`` run), a chain of direct successor
links (each process a peer linked to its successor only, gossip off), and that chain with a
second session in every process, a client of a router (``links``: what a node on direct links
would need, since a Zenoh router routes for clients and not between peers).

Issue 23 asks for a 255-node p99 round trip of at most 80 ms; this says how much of that a ring
of direct links could give before tokenring runs that way (its recovery would need a way to
the node after a dead one: the router's session). Each "pair" runs the three in turn, so that
the machine's slow and fast spells fall on all of them alike.

    python -m bench.topology --nodes 255 --pairs 3 --json bench/results/topology-255.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

TOPOLOGIES = ("router", "chain", "links")


def figures(rounds_s: list[float]) -> dict[str, float]:
    """Median and p99 of one run's round times, in ms."""
    ms = np.asarray(rounds_s) * 1e3
    return {"median_ms": round(float(np.median(ms)), 2), "p99_ms": round(float(np.percentile(ms, 99)), 2)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--nodes", type=int, default=255)
    p.add_argument("--pairs", type=int, default=3, help="times the three topologies run in turn")
    p.add_argument("--rounds", type=int, default=1000)
    p.add_argument("--warmup", type=int, default=100)
    p.add_argument("--timeout", type=float, default=600.0, help="one bare ring's time to form and run, s")
    p.add_argument("--json", metavar="FILE", help="write the runs and their summary here")
    args = p.parse_args(argv)
    if args.json and Path(args.json).exists():
        print(f"{args.json}: exists; not overwritten", file=sys.stderr)
        return 2
    from tokenring.perf import run_bare
    from tokenring.transport import use_host_runtime

    use_host_runtime()
    runs: list[dict[str, Any]] = []
    for pair in range(args.pairs):
        for topology in TOPOLOGIES:
            started = time.monotonic()
            rounds = run_bare(
                args.nodes,
                args.rounds,
                args.warmup,
                args.timeout,
                router=topology in ("router", "links"),
                chain=topology in ("chain", "links"),
            )
            run = {"pair": pair + 1, "topology": topology, **figures(rounds), "load": os.getloadavg()[0]}
            run["wall_s"] = round(time.monotonic() - started, 1)
            runs.append(run)
            print(
                f"pair {pair + 1}/{args.pairs} {topology:6}: median {run['median_ms']:.1f} ms, "
                f"p99 {run['p99_ms']:.1f} ms (load {run['load']:.1f}, {run['wall_s']:.0f} s)",
                flush=True,
            )
    summary = {
        topology: {
            key: round(float(np.median([r[key] for r in runs if r["topology"] == topology])), 2)
            for key in ("median_ms", "p99_ms")
        }
        for topology in TOPOLOGIES
    }
    for topology, row in summary.items():
        print(f"{topology:6}: median of medians {row['median_ms']:.1f} ms, of p99s {row['p99_ms']:.1f} ms")
    if args.json:
        out = {"benchmark": "bare Zenoh ring: router, chain, links", "nodes": args.nodes, "runs": runs}
        Path(args.json).write_text(json.dumps({**out, "summary": summary}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
