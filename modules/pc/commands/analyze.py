"""``tokenring analyze``: the seed's logfileanalyser — PNG plots and a summary of a data log."""

from __future__ import annotations

import argparse
import sys

HELP = "plot a localisation data log (paths, errors, steps, heading, sonar, time module)"

EXAMPLES = """examples:
  tokenring analyze logs/drive.trlog                   # the summary: end-point error, RMSE
  tokenring analyze logs/drive.trlog --out plots/      # and the PNGs
  tokenring analyze logs/drive.trlog --salvage --json  # a damaged log, read around the damage
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_json_option, with_examples

    p = sub.add_parser(
        "analyze",
        **with_examples(EXAMPLES),
        help=HELP,
        description="Write PNG plots of a data log like the seed's logfileanalyser — the paths of every "
        "position source against the truth, errors over time, step increments, heading, sonar distances "
        "and the time module (each sensor's and the synchronisation's cycle times, missed samples) — and "
        "print the end-point error and RMSE of every position source against the ground truth.",
    )
    p.add_argument("log", help="data log (.trlog)")
    p.add_argument("--out", metavar="DIR", help="directory for the PNGs (default: only the summary)")
    p.add_argument("--force", action="store_true", help="replace plots already in --out DIR")
    p.add_argument(
        "--salvage",
        action="store_true",
        help="read the records around damage inside the log (else damage is an error)",
    )
    add_json_option(p)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from modules.pc.analysis import PLOTS, analyse
    from tokenring import check_output, option_error
    from tokenring.cli import print_json

    if args.out:  # before the log is read and plotted
        check_output(args.out, (args.log,), directory=True, error=option_error("--out"))
        for name in PLOTS:
            if (Path(args.out) / name).exists():
                check_output(
                    Path(args.out) / name, (args.log,), force=args.force, error=option_error("--out")
                )

    def progress(name: str) -> None:
        if not args.json:
            print(f"  wrote {name}", file=sys.stderr)

    summary, files = analyse(args.log, args.out, progress, salvage=args.salvage)
    if args.json:
        print_json({**summary, "files": [str(f) for f in files]})
        return 0
    print(
        f"{summary['log']}: {summary['sync'].get('count', 0)} synchronisations"
        + (" (torn tail)" if summary["truncated"] else "")
    )
    sync = summary["sync"]
    if "median_period_ms" in sync:
        print(
            f"sync period: median {sync['median_period_ms']:.0f} ms, p99 {sync['p99_period_ms']:.0f} ms, "
            f"{100 * sync['within_2pct']:.0f} % within ±2 %"
            + (
                f", {100 * sync['within_98_102ms']:.0f} % within 98-102 ms (the seed: > 85 %)"
                if sync.get("within_98_102ms") is not None
                else ""
            )
        )
    for entry in summary["sources"].values():
        parts = [f"{entry['name']:>15}"]
        if "end_error_mm" in entry:
            parts.append(f"end error {entry['end_error_mm']:8.1f} mm  RMSE {entry['rmse_mm']:8.1f} mm")
        if "end_heading_error_deg" in entry:
            parts.append(
                f"heading end {entry['end_heading_error_deg']:+6.2f}°  RMSE {entry['heading_rmse_deg']:5.2f}°"
            )
        print("  ".join(parts))
    for sensor, t in summary["timing"].items():
        print(f"{sensor:>15}: {t['samples']} samples, {t['missed']} missed, {t['late']} out of order")
    if summary.get("filter_to_dead_reckoning") is not None:
        print(f"filter / dead reckoning end error: {summary['filter_to_dead_reckoning']:.3f}")
    return 0
