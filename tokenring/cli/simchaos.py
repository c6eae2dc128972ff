"""``tokenring sim --chaos FILE | --random A..B | --replay FILE``: chaos scenarios and seed
campaigns in virtual time (issue 55), judged as ``tokenring chaos`` judges real processes.

Kept apart from :mod:`tokenring.cli.commands.sim` (the ring alone, the robot) and out of the
verbs' folder (it is no verb): its options and its runs. Exit codes as ``tokenring chaos``: 0
every invariant held, 1 one broke (or a replay did not give the recorded frames), 2 bad input.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

MAX_SEED = 2**32 - 1
MAX_SEEDS = 10_000_000  # a campaign's seeds (a year of this machine)
MAX_SHRINK_RUNS = 10_000
DEFAULT_SHRINK_RUNS = 100  # a run is seconds here, not minutes: shrink hard
PROGRESS_S = 10.0  # a campaign's progress line at most this often
#: sim's options whose use with chaos in virtual time is checked (added to the parser before ours)
CHECKED = ("seed", "bitrate", "profile", "fault", "nodes", "no_world", "ledger", "logs")

EXAMPLES = """  tokenring sim --chaos scenarios/compound.yaml          # a scenario file in virtual time
  tokenring sim --chaos scenarios/every-fault.yaml --seed 9 --json -
  tokenring sim --random 1..1000 --duration 60 --jobs 2  # 1000 seeded schedules on both cores
  tokenring sim --random 1..200 --kinds crash,hang,lose --out failures/
  tokenring sim --replay failures/sim-seed17-min.yaml    # a failure, exactly again
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of chaos in virtual time, on ``tokenring sim``'s parser."""
    from tokenring.chaos.operations import OPERATIONS
    from tokenring.cli.args import int_within

    group = p.add_argument_group(
        "chaos in virtual time",
        "a tokenring chaos scenario, a campaign of seeded schedules, or a failure's replay file; "
        "exit code 0 every invariant held, 1 one broke, 2 bad input",
    )
    group.add_argument(
        "--chaos", metavar="SCENARIO", help="run a scenario file (as tokenring chaos takes it)"
    )
    group.add_argument(
        "--random",
        metavar="A..B",
        help="a campaign: seeds A to B (or one seed), each a schedule of --duration seconds drawn "
        "from it and run from it; failing seeds are written to --out with a shrunk schedule",
    )
    group.add_argument(
        "--replay", metavar="FILE", help="run a written failure (its seed and bitrate from its sim: section)"
    )
    group.add_argument(
        "--kinds", help=f"--random: comma-separated operations to draw (default all: {','.join(OPERATIONS)})"
    )
    group.add_argument(
        "--jobs",
        type=int_within(1, 64),
        default=1,
        metavar="N",
        help="--random: seeds on N processes at once",
    )
    group.add_argument(
        "--out",
        metavar="DIR",
        default=".",
        help="--random: where failing seeds are written (never overwritten)",
    )
    group.add_argument(
        "--shrink-runs",
        type=int_within(0, MAX_SHRINK_RUNS),
        default=DEFAULT_SHRINK_RUNS,
        metavar="N",
        help=f"--random: at most N runs to shrink a failing schedule (default {DEFAULT_SHRINK_RUNS}; 0: none)",
    )
    group.add_argument(
        "--downloads",
        action="store_true",
        help="--random: main downloads programs into the other nodes all along (ring.downloads)",
    )
    group.add_argument(
        "--stop-at-failure", action="store_true", help="--random: end the campaign at the first failing seed"
    )
    group.add_argument("--ledger", metavar="DIR", help="--chaos/--replay: keep the probes' ledgers in DIR")
    group.add_argument("--logs", metavar="FILE", help="--chaos/--replay: write the nodes' log lines to FILE")
    group.add_argument("--quiet", action="store_true", help="no progress lines")
    # what the user set is told from the parser's defaults (some of sim's options clash here)
    p.set_defaults(sim_defaults={name: p.get_default(name) for name in CHECKED})


def wanted(args: argparse.Namespace) -> bool:
    """Whether the command line asks for chaos in virtual time."""
    return bool(args.chaos or args.random or args.replay)


def run(args: argparse.Namespace) -> int:
    """Run what was asked (exit code as tokenring chaos's)."""
    from tokenring.cli.output import check_json_target, check_option_output
    from tokenring.errors import UsageError

    given = {name for name, default in args.sim_defaults.items() if getattr(args, name) != default}

    chosen = [name for name in ("chaos", "random", "replay") if getattr(args, name)]
    if len(chosen) > 1:
        raise UsageError(f"--{chosen[0]} and --{chosen[1]}: give one of --chaos, --random, --replay")
    clash = sorted(given & {"fault", "nodes", "no_world"})
    if clash:
        raise UsageError(
            f"--{clash[0].replace('_', '-')} does not go with --{chosen[0]}: the scenario names the nodes and faults"
        )
    check_json_target(args.json, args.force)
    if args.logs:
        check_option_output("--logs", args.logs, args.force)

    def progress(text: str) -> None:
        if not args.quiet:
            print(f"sim | {text}", file=sys.stderr, flush=True)

    if args.random:
        return _campaign(args, given, progress)
    return _scenario(args, given, progress)


def _scenario(args: argparse.Namespace, given: set[str], progress: Any) -> int:
    from tokenring.chaos.runner import format_report, load_scenario
    from tokenring.chaos.virtual import run_virtual
    from tokenring.cli.output import write_json
    from tokenring.contract.protocol import load_protocol
    from tokenring.contract.ring import parse_bitrate
    from tokenring.errors import UsageError

    protocol = load_protocol(args.protocol)
    path = args.replay or args.chaos
    scenario = load_scenario(path, protocol)
    recorded = scenario.sim if args.replay else {}
    if args.replay and not recorded:
        raise UsageError(f"{path}: no sim: section (seed, bitrate): not a replay file; run it with --chaos")
    for option in ("seed", "bitrate", "profile"):
        if args.replay and option in given and option in recorded:
            raise UsageError(f"--{option} does not go with --replay: {path} gives it ({recorded[option]})")
    seed = recorded.get("seed", args.seed)
    bitrate_text = recorded.get("bitrate", args.bitrate)
    profile = recorded.get("profile", args.profile) if args.replay else args.profile
    bitrate = parse_bitrate(bitrate_text)
    if bitrate is None:
        raise UsageError("--bitrate max has no wire time: in virtual time give a bitrate, e.g. 2.5M")
    run = run_virtual(
        scenario, protocol, seed=seed, bitrate=bitrate, profile=profile, ledger_dir=args.ledger,
        logs=args.logs, progress=progress,
    )  # fmt: skip
    report = run.report
    virtual = report["virtual"]
    same = None
    if args.replay and "frames_sha256" in recorded:
        same = recorded["frames_sha256"] == virtual["frames_sha256"]
        report["replay"] = {"recorded_frames_sha256": recorded["frames_sha256"], "same_frames": same}
    if args.json != "-":
        sys.stdout.write(format_report(report))
        print(
            f"\nvirtual time: seed {seed}, bitrate {bitrate_text}, {virtual['simulated_s']:.3f} simulated s "
            f"in {virtual['real_s']:.2f} real s ({virtual['speedup']:.1f}x), {virtual['frames']} frames"
        )
        print(f"frames_sha256 {virtual['frames_sha256']}")
        if same is not None:
            print(
                "replayed exactly: the same frames as the recorded run"
                if same
                else f"NOT the recorded run: its frames were {recorded['frames_sha256']}"
            )
    if args.json:
        write_json(args.json, report)
    return 0 if report["ok"] and same is not False else 1


def parse_seeds(text: str) -> range:
    """``A..B`` (inclusive) or one seed, within 0..2^32-1; UsageError naming --random."""
    from tokenring.errors import UsageError

    first, dots, last = text.partition("..")
    try:
        low = int(first)
        high = int(last) if dots else low
    except ValueError:
        raise UsageError(f"--random {text}: expected seeds A..B (e.g. 1..1000) or one seed") from None
    if not 0 <= low <= high <= MAX_SEED:
        raise UsageError(f"--random {text}: seeds within 0..{MAX_SEED}, the first not after the last")
    if high - low + 1 > MAX_SEEDS:
        raise UsageError(f"--random {text}: at most {MAX_SEEDS} seeds in one campaign")
    return range(low, high + 1)


def _campaign(args: argparse.Namespace, given: set[str], progress: Any) -> int:
    import time
    from pathlib import Path

    from tokenring.chaos.campaign import CampaignSpec, run_campaign
    from tokenring.chaos.operations import OPERATIONS
    from tokenring.cli.output import write_json
    from tokenring.contract.protocol import load_protocol
    from tokenring.contract.ring import parse_bitrate
    from tokenring.errors import UsageError

    seeds = parse_seeds(args.random)
    clash = sorted(given & {"seed", "ledger", "logs"})
    if clash:
        raise UsageError(f"--{clash[0]} does not go with --random: every seed is its own run")
    if not 5 <= args.duration <= 86400:
        raise UsageError(f"--duration {args.duration:g}: seconds from 5 to 86400 for --random")
    kinds = [k.strip() for k in args.kinds.split(",")] if args.kinds else list(OPERATIONS)
    unknown = [k for k in kinds if k not in OPERATIONS]
    if unknown or not kinds:
        raise UsageError(
            f"--kinds: unknown operation {unknown[0] if unknown else ''!r} (known: {', '.join(OPERATIONS)})"
        )
    out = Path(args.out)
    if not out.is_dir():
        raise UsageError(f"--out {out}: {'not a directory' if out.exists() else 'no such directory'}")
    if parse_bitrate(args.bitrate) is None:
        raise UsageError("--bitrate max has no wire time: in virtual time give a bitrate, e.g. 2.5M")
    protocol = load_protocol(args.protocol)
    spec = CampaignSpec(
        duration_s=args.duration,
        kinds=tuple(kinds),
        bitrate=args.bitrate,
        profile=args.profile,
        out=str(out),
        shrink_runs=args.shrink_runs,
        nodes=tuple(n.name for n in protocol.default_nodes),
        downloads=args.downloads,
    )
    progress(
        f"seeds {seeds.start}..{seeds.stop - 1} ({len(seeds)}), {args.duration:g} simulated s each, {args.jobs} job(s)"
    )
    last_line = [time.monotonic()]

    def on_outcome(outcome: dict[str, Any], result: Any) -> None:
        if not outcome["ok"]:
            shrunk = outcome.get("shrunk")
            progress(
                f"seed {outcome['seed']} FAILED ({', '.join(outcome['broken'])}): {outcome['file']}"
                + (f"; shrunk to {shrunk['operations']} operations: {shrunk['file']}" if shrunk else "")
            )
        if time.monotonic() - last_line[0] >= PROGRESS_S or result.seeds == len(seeds):
            last_line[0] = time.monotonic()
            progress(
                f"{result.seeds}/{len(seeds)} seeds, {len(result.failed)} failed, "
                f"{result.per_hour:.0f} schedules/hour"
            )

    result = run_campaign(
        seeds, spec, jobs=args.jobs, on_outcome=on_outcome, stop_at_failure=args.stop_at_failure
    )
    data = result.as_dict()
    if args.json != "-":
        c = result.commands
        print(
            f"{result.seeds} seeds{' (interrupted)' if result.interrupted else ''}: "
            f"{result.seeds - len(result.failed)} ok, {len(result.failed)} failed; "
            f"{result.simulated_s:.0f} simulated s in {result.wall_s:.1f} s on {result.jobs} job(s) "
            f"({result.per_hour:.0f} schedules/hour); {result.faults} faults, {result.regenerations} regenerations; "
            f"commands sent {c['sent']}, acknowledged {c['acked']}, lost {c['lost']}, duplicated {c['duplicated']}"
            + (
                f"; downloads {result.downloads['completed']} of {result.downloads['attempted']} completed"
                if args.downloads
                else ""
            )
        )
        for failure in result.failed:
            print(f"  seed {failure['seed']}: {', '.join(failure['broken'])}  {failure.get('file', '')}")
    if args.json:
        write_json(args.json, data)
    if result.interrupted:
        return 130
    return 1 if result.failed else 0
