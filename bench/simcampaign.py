"""A timed seed campaign in virtual time (issue 55): ``python -m bench.simcampaign --minutes M``.

Runs ``tokenring sim --random`` over consecutive seeds, each a schedule of ``--duration``
simulated seconds drawn by the nemesis and judged by the chaos invariants, for M wall minutes on
``--jobs`` processes, in chunks of seeds sized to end in time. Writes the
campaign's figures — seeds run, simulated time, faults injected, commands sent / acknowledged /
lost / duplicated, failures, schedules per hour — with the machine's load average over the run to
``bench/results/simcampaign-<date>.json`` (``bench/RESULTS.md`` shows the newest). A failing
seed's replay files are kept beside it, in ``simcampaign-<date>-failures/``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.mutants import check_imported, environment, head_commit, package_copy

RESULTS = Path(__file__).with_name("results")
DURATION_S = 60.0  # the measure: schedules of 60 simulated seconds
CHUNK_S = 120.0  # wall seconds a chunk of seeds aims at (the load is sampled between chunks)
COMMAND_KEYS = ("sent", "acked", "unacked", "untransmitted", "taken", "lost", "duplicated", "phantom")


def chunk(first: int, count: int, args: argparse.Namespace, scratch: Path) -> dict[str, Any]:
    """``tokenring sim --random`` over ``count`` seeds from ``first`` with the committed build
    (``args.build``, a copy of it: never the work tree's uncommitted edits): its ``--json`` figures."""
    report = scratch / f"campaign-{first}.json"
    argv = [sys.executable, "-m", "tokenring", "sim", "--random", f"{first}..{first + count - 1}",
            "--duration", f"{args.duration:g}", "--jobs", str(args.jobs), "--shrink-runs", str(args.shrink_runs),
            "--out", str(scratch), "--json", str(report), "--quiet"]  # fmt: skip
    done = subprocess.run(argv, capture_output=True, text=True, cwd=args.build, env=environment(args.build))
    if not report.exists():
        raise SystemExit(f"seeds {first}..{first + count - 1} wrote no report: {done.stderr.strip()[-600:]}")
    data: dict[str, Any] = json.loads(report.read_text())
    return data


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Consecutive chunks of seeds, each sized to end before ``args.minutes`` are up; the sums.

    Chunks, not one campaign stopped by Ctrl-C: a seed under way does not stop on Ctrl-C (the
    simulation takes the KeyboardInterrupt for one task's failure and runs on)."""
    totals: dict[str, Any] = {"seeds": 0, "simulated_s": 0.0, "cpu_s": 0.0, "operations": 0, "faults": 0,
                              "regenerations": 0, "commands": dict.fromkeys(COMMAND_KEYS, 0), "failed": []}  # fmt: skip
    loads = [os.getloadavg()[0]]
    started = time.monotonic()
    ends = started + args.minutes * 60
    first = args.first
    per_seed = None  # wall seconds per seed on all jobs, as measured so far
    with tempfile.TemporaryDirectory(prefix="simcampaign-") as scratch:
        args.commit = head_commit()
        args.build = package_copy(Path(scratch) / "build", None, args.commit)
        check_imported(args.build, None)
        while True:
            left = ends - time.monotonic()
            if per_seed is None:
                count = 4 * args.jobs
            else:
                count = min(int(left / per_seed), int(CHUNK_S / per_seed))
                count -= count % args.jobs
            if count < args.jobs or left <= 0:
                break
            data = chunk(first, count, args, Path(scratch))
            loads.append(os.getloadavg()[0])
            first += count
            for key in ("seeds", "simulated_s", "cpu_s", "operations", "faults", "regenerations"):
                totals[key] += data[key]
            for key in COMMAND_KEYS:
                totals["commands"][key] += data["commands"][key]
            totals["failed"] += data["failed"]
            per_seed = (time.monotonic() - started) / totals["seeds"]
        wall = time.monotonic() - started
        date = time.strftime("%Y-%m-%d")
        kept = []
        if totals["failed"]:
            keep = RESULTS / f"simcampaign-{date}-failures"
            keep.mkdir(parents=True, exist_ok=True)
            for path in sorted(Path(scratch).glob("sim-seed*.yaml")):
                shutil.copy2(path, keep / path.name)
                kept.append(f"{keep.name}/{path.name}")
    return {
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "command": "python -m bench.simcampaign " + " ".join(args.argv),
        "commit": args.commit,
        "minutes": args.minutes,
        "jobs": args.jobs,
        "cpus": os.cpu_count(),
        "duration_s": args.duration,
        "first_seed": args.first,
        "last_seed": first - 1,
        "seeds": totals["seeds"],
        "wall_s": round(wall, 1),
        "simulated_s": round(totals["simulated_s"], 1),
        "simulated_h": round(totals["simulated_s"] / 3600, 3),
        "schedules_per_hour": round(totals["seeds"] * 3600 / wall, 1) if wall > 0 else None,
        "speedup_per_job": round(totals["simulated_s"] / totals["cpu_s"], 2) if totals["cpu_s"] else None,
        "operations": totals["operations"],
        "faults": totals["faults"],
        "regenerations": totals["regenerations"],
        "commands": totals["commands"],
        "failures": len(totals["failed"]),
        "failed": [{k: f[k] for k in ("seed", "broken") if k in f} for f in totals["failed"]],
        "failure_files": kept,
        "load_1min": {
            "start": round(loads[0], 2),
            "end": round(loads[-1], 2),
            "median": round(statistics.median(loads), 2),
            "max": round(max(loads), 2),
        },
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.simcampaign", description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0, help="wall minutes to run (default 60)")
    parser.add_argument("--jobs", type=int, default=2, help="seeds on this many processes at once")
    parser.add_argument("--duration", type=float, default=DURATION_S, help="simulated seconds per schedule")
    parser.add_argument("--first", type=int, default=1, help="the first seed (default 1)")
    parser.add_argument(
        "--shrink-runs", type=int, default=20, help="runs to shrink a failing seed's schedule"
    )
    parser.add_argument("--json", type=Path, help="default bench/results/simcampaign-<date>.json")
    args = parser.parse_args(argv)
    args.argv = argv if argv is not None else sys.argv[1:]
    result = run(args)
    path = args.json or RESULTS / f"simcampaign-{result['date'][:10]}.json"
    path.write_text(json.dumps(result, indent=1) + "\n")
    c = result["commands"]
    print(
        f"{result['seeds']} seeds in {result['wall_s'] / 60:.1f} min on {result['jobs']} jobs "
        f"({result['schedules_per_hour']:.0f} schedules/hour), {result['simulated_h']:.2f} simulated h, "
        f"{result['faults']} faults; commands sent {c['sent']}, acknowledged {c['acked']}, lost {c['lost']}, "
        f"duplicated {c['duplicated']}; {result['failures']} failures; load {result['load_1min']['median']} "
        f"(median); written {path}",
        file=sys.stderr,
    )
    return 1 if result["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
