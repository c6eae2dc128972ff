"""Seeded random chaos runs, one after the other: ``python -m bench.nemesis``.

Runs ``tokenring chaos --random SEED`` for each seed (no shrinking) and keeps a compact
summary per run — operations, faults injected, commands sent / acknowledged / lost /
duplicated, tokens regenerated, one token at the end, the verdict — in
``bench/results/nemesis-<date>.json`` (kilobytes), and prints a Markdown table for
``bench/RESULTS.md``. ``--soak S`` adds one run of S seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).with_name("results")


def run_seed(seed: int, duration: float, timeout: float) -> dict[str, Any]:
    """One ``tokenring chaos --random`` run, summarised."""
    with tempfile.TemporaryDirectory(prefix="nemesis-") as scratch:
        report_file = Path(scratch) / "report.json"
        argv = [sys.executable, "-m", "tokenring", "chaos", "--random", str(seed), "--duration", str(duration),
                "--out", scratch, "--json", str(report_file), "--quiet", "--shrink-runs", "0"]  # fmt: skip
        started = time.monotonic()
        load = os.getloadavg()[0]
        try:
            done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"seed": seed, "duration_s": duration, "error": f"no verdict within {timeout:.0f} s"}
        wall = time.monotonic() - started
        if not report_file.exists():
            return {"seed": seed, "duration_s": duration, "error": done.stderr.strip()[-400:]}
        report = json.loads(report_file.read_text())
    commands = report.get("commands", {})
    return {
        "seed": seed,
        "duration_s": duration,
        "exit": done.returncode,
        "ok": report["ok"],
        "operations": report.get("operations"),
        "faults": len(report["faults"]),
        "regenerated": sum(s["tokens_regenerated"] for s in report["faults"]),
        "sent": commands.get("sent"),
        "acked": commands.get("acked"),
        "taken": commands.get("taken"),
        "lost": commands.get("lost"),
        "duplicated": commands.get("duplicated"),
        "phantom": commands.get("phantom"),
        "lost_at_receiver_crash": commands.get("lost_at_receiver_crash"),
        "one_token_at_end": report["invariants"]["exactly_one_token_at_end"],
        "broken": sorted(k for k, v in report["invariants"].items() if not v),
        # what a failure needs to be looked into, kept short
        "injection_errors": [f"{s['at']} {s['kind']} {e}" for s in report["faults"] for e in s["errors"]][:5],
        "unrecovered": [
            f"{s['at']} {s['kind']} {s['node']}" for s in report["faults"] if s["recovered_ms"] is None
        ][:5],
        "converged_s": report["end"].get("converged_after_last_fault_s"),
        "wall_s": round(wall, 1),
        "load_1min_at_start": round(load, 2),
    }


def table(runs: list[dict[str, Any]]) -> str:
    """The runs as a Markdown table with a total row."""
    head = "| seed | s | faults | regen | sent | acked | lost | dup | one token | verdict |\n|---|---|---|---|---|---|---|---|---|---|\n"
    rows = []
    for r in runs:
        if "error" in r:
            rows.append(f"| {r['seed']} | {r['duration_s']:g} | | | | | | | | error: {r['error'][:60]} |")
            continue
        verdict = "ok" if r["ok"] else "FAIL " + ", ".join(r["broken"])
        rows.append(
            f"| {r['seed']} | {r['duration_s']:g} | {r['faults']} | {r['regenerated']} | {r['sent']} | "
            f"{r['acked']} | {r['lost']} | {r['duplicated']} | {'yes' if r['one_token_at_end'] else 'NO'} | {verdict} |"
        )
    good = [r for r in runs if "error" not in r]
    total = (
        f"| **all {len(runs)}** | {sum(r['duration_s'] for r in runs):g} | {sum(r['faults'] for r in good)} | "
        f"{sum(r['regenerated'] for r in good)} | {sum(r['sent'] for r in good)} | {sum(r['acked'] for r in good)} | "
        f"{sum(r['lost'] for r in good)} | {sum(r['duplicated'] for r in good)} | "
        f"{sum(1 for r in good if r['one_token_at_end'])}/{len(runs)} | {sum(1 for r in good if r['ok'])}/{len(runs)} ok |"
    )
    return head + "\n".join(rows) + "\n" + total + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.nemesis", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--seeds", type=int, default=20, help="how many seeds, 1..N (default 20)")
    parser.add_argument("--first", type=int, default=1, help="the first seed (default 1)")
    parser.add_argument("--duration", type=float, default=60.0, help="seconds per run (default 60)")
    parser.add_argument("--soak", type=float, default=0.0, help="add one run of this many seconds")
    parser.add_argument(
        "--list", default="", help="these seeds instead (comma-separated), e.g. to rerun failures"
    )
    parser.add_argument(
        "--out", default=None, help="the summary JSON (default bench/results/nemesis-<date>.json)"
    )
    args = parser.parse_args(argv)
    out = Path(args.out) if args.out else RESULTS / f"nemesis-{time.strftime('%Y-%m-%d-%H%M%S')}.json"
    if out.exists():
        print(f"{out}: exists; not overwritten", file=sys.stderr)
        return 2
    seeds = (
        [int(x) for x in args.list.split(",")] if args.list else [args.first + i for i in range(args.seeds)]
    )
    plan = [(seed, args.duration) for seed in seeds]
    if args.soak:
        plan.append((max(seeds, default=args.first) + 1, args.soak))
    runs = []
    for index, (seed, duration) in enumerate(plan, 1):
        print(f"[{index}/{len(plan)}] seed {seed}, {duration:g} s ...", file=sys.stderr, flush=True)
        runs.append(run_seed(seed, duration, timeout=duration * 3 + 300))
        r = runs[-1]
        print(f"    {'error: ' + r['error'] if 'error' in r else ('ok' if r['ok'] else 'FAIL ' + str(r['broken']))}",
              file=sys.stderr, flush=True)  # fmt: skip
        out.write_text(json.dumps({"runs": runs}, indent=1) + "\n")
    print(table(runs))
    return 0 if all(r.get("ok") for r in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
