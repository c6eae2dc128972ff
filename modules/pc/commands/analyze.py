"""``tokenring analyze``: the seed's logfileanalyser — PNG plots and a summary of a data log, and
the seed's own output (its per-module data files and gnuplot control files, table B.9)."""

from __future__ import annotations

import argparse
import sys

HELP = "plot a localisation data log (paths, errors, steps, heading, sonar, time module)"

EXAMPLES = """examples:
  tokenring analyze logs/drive.trlog                   # the summary: end-point error, RMSE
  tokenring analyze logs/drive.trlog --out plots/      # and the PNGs
  tokenring analyze logs/drive.trlog --salvage --json  # a damaged log, read around the damage
  tokenring analyze logs/drive.trlog --seed-out seed/  # the seed's files and seed/logfile.cfg;
                                                       # then: cd seed/position && gnuplot command
  tokenring analyze logs/drive.trlog --seed-out seed/ --seed-config my.cfg --force
                                                       # my.cfg: a table B.2 file, e.g. a copy of
                                                       # seed/logfile.cfg edited (terminals, styles)
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
        "print the end-point error and RMSE of every position source against the ground truth. With "
        "--seed-out DIR also the seed's own output (seed 000, §9.2): per module a directory of data files "
        "in table B.9's widths and a gnuplot control file 'command', and DIR/logfile.cfg in table B.2's "
        "format; a module the log has no data for (no LOPS, no gyroscope) gets no directory and one line "
        "saying so.",
    )
    p.add_argument("log", help="data log (.trlog)")
    p.add_argument("--out", metavar="DIR", help="directory for the PNGs (default: only the summary)")
    p.add_argument(
        "--seed-out",
        metavar="DIR",
        help="write the seed's logfileanalyser output into DIR (seed 000, §9.2, table B.9): one "
        "subdirectory per module (position, odometrie, gyroskop, lops, sonar, time) with its data "
        "files and a gnuplot control file 'command' (run 'gnuplot command' inside it), and "
        "DIR/logfile.cfg, the configuration in table B.2's format",
    )
    p.add_argument(
        "--seed-config",
        metavar="FILE",
        help="a table B.2 file (the seed's logfile.cfg) for --seed-out: its plot switches, gnuplot "
        "terminals, styles, positions and timed sensors (its log and output names: the command line's)",
    )
    p.add_argument(
        "--force", action="store_true", help="replace plots already in --out DIR, or --seed-out DIR's files"
    )
    p.add_argument(
        "--salvage",
        action="store_true",
        help="read the records around damage inside the log (else damage is an error)",
    )
    add_json_option(p)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from modules.localization.logs import read_log
    from modules.pc.analysis import PLOTS, analyse_log
    from tokenring import UsageError, check_output, option_error
    from tokenring.cli import print_json

    if args.seed_config and not args.seed_out:
        raise UsageError("--seed-config configures the seed's output: give its directory with --seed-out DIR")
    if args.out:  # before the log is read and plotted
        check_output(args.out, (args.log,), directory=True, error=option_error("--out"))
        for name in PLOTS:
            if (Path(args.out) / name).exists():
                check_output(
                    Path(args.out) / name, (args.log,), force=args.force, error=option_error("--out")
                )
    seed_config = None
    if args.seed_out:
        from modules.pc.seedplots import read_config

        check_seed_out(args)
        seed_config = read_config(args.seed_config) if args.seed_config else None

    def progress(name: str) -> None:
        if not args.json:
            print(f"  wrote {name}", file=sys.stderr)

    log = read_log(args.log, expect="data", salvage=args.salvage)
    summary, files = analyse_log(log, args.out, progress)
    seed = None
    if args.seed_out:
        from modules.pc.seedplots import write_seed_out

        seed = write_seed_out(log.records, args.seed_out, seed_config, args.log, progress)
        if not args.json:
            for note in seed["notes"]:
                print(f"  {note}", file=sys.stderr)
    if args.json:
        print_json({**summary, "files": [str(f) for f in files], **({"seed_out": seed} if seed else {})})
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
    if seed is not None:
        made = ", ".join(f"{name}/" for name in seed["modules"]) or "no module"
        print(f"{seed['dir']}: {made} and logfile.cfg; run 'gnuplot command' in each")
    return 0


def check_seed_out(args: argparse.Namespace) -> None:
    """Before the log is read: ``--seed-out DIR`` replaces none of its modules' directories nor
    its ``logfile.cfg`` without ``--force``, and never one that is or holds an input."""
    import os
    from pathlib import Path

    from modules.pc.seedplots import existing_outputs
    from tokenring import check_output, option_error

    error = option_error("--seed-out")
    inputs = [Path(p) for p in (args.log, args.seed_config) if p]
    check_output(args.seed_out, tuple(inputs), directory=True, error=error)
    for path in existing_outputs(Path(args.seed_out)):
        for source in inputs:
            inside = (
                source.exists()
                and path.exists()
                and (os.path.samefile(source, path) or path.resolve() in source.resolve().parents)
            )
            if inside:
                what = "is" if os.path.samefile(source, path) else "holds"
                raise error(str(path), f"{what} the input {source}; write the output to another path")
        if not args.force:
            raise error(str(path), "exists; give --force to replace it, or another path")
