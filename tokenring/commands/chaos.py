"""``tokenring chaos``: run a scripted list of faults against a ring and judge its recovery."""

from __future__ import annotations

import argparse
import sys

from tokenring import keys
from tokenring.chaos import format_report, load_scenario, run_scenario
from tokenring.cliutil import write_json


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "chaos",
        help="run a timed fault scenario against a ring and report recovery",
        description="Run SCENARIO.yaml (a timed list of faults, see scenarios/) against a ring it "
        "launches, or against a running one with --ring, watch the wire and report per fault the "
        "time to recover, tokens regenerated, duplicates eliminated, CRC rejects and commands lost "
        "or duplicated. Exit code 1 if a fault did not recover or an invariant broke.",
    )
    p.add_argument("scenario", help="scenario file (YAML)")
    p.add_argument("--ring", help="use this running ring instead of launching one")
    p.add_argument(
        "-e",
        "--connect",
        metavar="ENDPOINT",
        help=f"endpoint of the running ring (default {keys.DEFAULT_ENDPOINT})",
    )
    p.add_argument("--json", metavar="FILE", help="write the full report as JSON ('-' for stdout)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--logs", metavar="FILE", help="write the launched nodes' log lines to FILE")


def run(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    ring = keys.check_ring_name(args.ring) if args.ring else None

    def progress(text: str) -> None:
        if not args.quiet:
            print(f"chaos | {text}", file=sys.stderr, flush=True)

    report = run_scenario(scenario, ring=ring, endpoint=args.connect, progress=progress, log_file=args.logs)
    if args.json != "-":
        sys.stdout.write(format_report(report))
    if args.json:
        write_json(args.json, report)
    return 0 if report["ok"] else 1
