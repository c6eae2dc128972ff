"""``tokenring chaos``: run a scripted or seeded list of faults against a ring and judge it."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from tokenring.cli.args import int_within, seconds

if TYPE_CHECKING:
    from tokenring.chaos.nemesis import Operation

HELP = "run a timed fault scenario (or a seeded random one) against a ring and judge it"

MAX_SEED = 2**32 - 1  # a seed's range, as the world's
MAX_SHRINK_RUNS = 1000  # each run is a whole scenario: more would take weeks

EXAMPLES = """examples:
  tokenring chaos scenarios/every-fault.yaml          every fault kind once, judged
  tokenring chaos scenarios/compound.yaml --json -    overlapping faults, the report as JSON
  tokenring chaos --random 7 --duration 60            a schedule drawn from seed 7, run and judged
  tokenring chaos --random 7 --dry-run                only write seed 7's schedule
  tokenring chaos --random 3 --kinds crash,hang,lose  only these operations
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.chaos.operations import OPERATIONS
    from tokenring.contract import keys

    p = sub.add_parser(
        "chaos",
        help=HELP,
        description="Run SCENARIO.yaml (a timed list of faults, see scenarios/) against a ring it "
        "launches, or against a running one with --ring, or draw a schedule of overlapping faults "
        "from a seed with --random. Reports per fault the time to recover, tokens regenerated, "
        "duplicates eliminated and CRC rejects; at the end the workload stops, its last commands "
        "land, and the probes' ledgers are compared: commands acknowledged but never taken (lost), "
        "taken twice, and whether exactly one token circulates. A failing --random run is shrunk "
        "to a smaller schedule that still fails, written beside the first. Exit codes: 0 every "
        "invariant held, 1 one broke, 2 bad input.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("scenario", nargs="?", help="scenario file (YAML); or use --random")
    p.add_argument(
        "--random",
        metavar="SEED",
        type=int_within(0, MAX_SEED),
        help=f"draw the schedule from this seed (0..{MAX_SEED})",
    )
    p.add_argument(
        "--duration", type=seconds, default=60.0, help="--random: seconds of faults and settling (default 60)"
    )
    p.add_argument(
        "--kinds",
        help=f"--random: comma-separated operations to draw (default all: {','.join(OPERATIONS)})",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        default=".",
        help="--random: where the schedule (and a shrunk one) is written (default .; never overwritten)",
    )
    p.add_argument(
        "--shrink-runs",
        type=int_within(0, MAX_SHRINK_RUNS),
        default=6,
        metavar="N",
        help=f"--random: at most N runs to shrink a failing schedule (default 6, at most {MAX_SHRINK_RUNS}; "
        "0: no shrinking)",
    )
    p.add_argument("--dry-run", action="store_true", help="--random: write the schedule, run nothing")
    p.add_argument("--ring", help="use this running ring instead of launching one")
    p.add_argument(
        "-e",
        "--connect",
        metavar="ENDPOINT",
        help=f"endpoint of the running ring (default {keys.DEFAULT_ENDPOINT})",
    )
    p.add_argument("--json", metavar="FILE", help="write the full report as JSON ('-' for stdout)")
    p.add_argument("--force", action="store_true", help="replace an existing --json or --logs file")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--logs", metavar="FILE", help="write the launched nodes' log lines to FILE")
    p.add_argument(
        "--ledger", metavar="DIR", help="keep the probes' command ledgers in DIR (default: a temporary one)"
    )


def _check(args: argparse.Namespace) -> list[str]:
    from pathlib import Path

    from tokenring.chaos.operations import OPERATIONS
    from tokenring.errors import UsageError

    if (args.scenario is None) == (args.random is None):
        raise UsageError("give a scenario file or --random SEED (one of them)")
    if args.ledger:
        ledger = Path(args.ledger)
        if ledger.exists() and not ledger.is_dir():
            raise UsageError(f"--ledger {ledger}: not a directory")
        if ledger.is_dir() and any(ledger.glob("ledger-*.jsonl")):
            raise UsageError(
                f"--ledger {ledger}: holds ledgers of an earlier run; give an empty or new directory"
            )
    if args.random is None:
        return []
    if args.ring:
        raise UsageError("--random launches its own ring (respawn on): drop --ring")
    if args.random < 0:
        raise UsageError(f"--random {args.random}: a seed is a whole number >= 0")
    if not 5 <= args.duration <= 86400:
        raise UsageError(f"--duration {args.duration:g}: seconds from 5 to 86400")
    if args.shrink_runs < 0:
        raise UsageError(f"--shrink-runs {args.shrink_runs}: 0 or more")
    kinds = [k.strip() for k in args.kinds.split(",")] if args.kinds else list(OPERATIONS)
    unknown = [k for k in kinds if k not in OPERATIONS]
    if unknown or not kinds:
        raise UsageError(
            f"--kinds: unknown operation {unknown[0] if unknown else ''!r} (known: {', '.join(OPERATIONS)})"
        )
    out = Path(args.out)
    if not out.is_dir():
        raise UsageError(f"--out {out}: {'not a directory' if out.exists() else 'no such directory'}")
    return kinds


def run(args: argparse.Namespace) -> int:
    from tokenring.chaos.runner import load_scenario, run_scenario
    from tokenring.cli.output import check_json_target, check_option_output
    from tokenring.contract import keys

    check_json_target(args.json, args.force)
    if args.logs:
        check_option_output("--logs", args.logs, args.force)
    kinds = _check(args)
    ring = keys.check_ring_name(args.ring) if args.ring else None

    def progress(text: str) -> None:
        if not args.quiet:
            print(f"chaos | {text}", file=sys.stderr, flush=True)

    if args.random is None:
        scenario = load_scenario(args.scenario)
        report = run_scenario(
            scenario, ring=ring, endpoint=args.connect, progress=progress, log_file=args.logs,
            ledger_dir=args.ledger,
        )  # fmt: skip
        return _finish(args, report)
    return _run_random(args, kinds, progress)


def _run_random(args: argparse.Namespace, kinds: list[str], progress: Any) -> int:
    import tempfile
    from pathlib import Path

    from tokenring.chaos.campaign import unique_path
    from tokenring.chaos.nemesis import generate, scenario_document, shrink
    from tokenring.chaos.runner import load_scenario, run_scenario
    from tokenring.contract.protocol import default_protocol
    from tokenring.errors import UsageError

    protocol = default_protocol()
    names = [n.name for n in protocol.default_nodes]
    settle = 3.0
    ops = generate(args.random, names, duration=args.duration, settle=settle, kinds=kinds)
    if not ops:
        raise UsageError(f"--duration {args.duration:g} leaves no room for a fault: give more")
    comment = (
        f"tokenring chaos --random {args.random} --duration {args.duration:g}"
        + (f" --kinds {','.join(kinds)}" if args.kinds else "")
        + f"\n{len(ops)} operations drawn from seed {args.random}; rerun with: tokenring chaos THIS_FILE"
    )
    out = Path(args.out)
    path = unique_path(out, f"chaos-seed{args.random}", ".yaml")
    path.write_text(scenario_document(ops, settle=settle, comment=comment))
    progress(f"schedule of seed {args.random}: {len(ops)} operations, written to {path}")
    if args.dry_run:
        print(path)
        return 0

    def attempt(candidate: list[Operation], label: str) -> dict[str, Any]:
        with tempfile.TemporaryDirectory(prefix="tokenring-chaos-") as scratch:
            file = Path(scratch) / f"{label}.yaml"
            file.write_text(scenario_document(candidate, settle=settle))
            report = run_scenario(
                load_scenario(file), progress=progress, log_file=args.logs, ledger_dir=args.ledger
            )
        report["scenario"] = str(path) if label == "drawn" else label
        return report

    report = attempt(ops, "drawn")
    report["seed"] = args.random
    report["operations"] = len(ops)
    if not report["ok"] and args.shrink_runs:
        broken = sorted(name for name, ok in report["invariants"].items() if not ok)
        progress(f"failed ({', '.join(broken)}): shrinking, at most {args.shrink_runs} runs")

        def still_fails(candidate: list[Operation]) -> bool:
            return not attempt(candidate, "candidate")["ok"]

        smallest, runs = shrink(ops, still_fails, args.shrink_runs, progress)
        shrunk = unique_path(out, f"chaos-seed{args.random}-min", ".yaml")
        shrunk.write_text(
            scenario_document(
                smallest,
                settle=settle,
                comment=f"shrunk from {path} ({len(ops)} operations) in {runs} runs: {len(smallest)} still fail",
            )
        )
        report["shrunk"] = {"file": str(shrunk), "operations": len(smallest), "runs": runs}
        progress(f"smallest failing schedule: {len(smallest)} operations, written to {shrunk}")
    return _finish(args, report)


def _finish(args: argparse.Namespace, report: dict[str, Any]) -> int:
    from tokenring.chaos.runner import format_report
    from tokenring.cli.output import write_json

    if args.json != "-":
        sys.stdout.write(format_report(report))
    if args.json:
        write_json(args.json, report)
    return 0 if report["ok"] else 1
