"""``tokenring log``: the seed's log helpers — convert (text, the seed's appendix B lines, table
B.8's data.dat and sonar.dat, CSV, MCAP), sort, info."""

from __future__ import annotations

import argparse
import sys

HELP = "convert, sort or summarise a localisation data or error log"

CONVERT_EXAMPLES = """examples:
  tokenring log convert logs/drive.trlog > drive.txt                 # the seed's text, to stdout
  tokenring log convert logs/drive.trlog --to seed --out drive.log   # appendix B's line formats
  tokenring log convert logs/drive.trlog --to dat --out drive-dat/   # table B.8's data.dat, sonar.dat
  tokenring log convert logs/drive.trlog --to csv --out drive-csv/   # data.csv and sonar.csv
  tokenring log convert logs/drive.trlog --to mcap --out drive.mcap  # for Foxglove, PlotJuggler
"""
SORT_EXAMPLES = """examples:
  tokenring log sort logs/drive.trlog --out sorted.trlog
  tokenring log sort logs/drive.trlog --out sorted.trlog --force    # replace an older sorted.trlog
"""
INFO_EXAMPLES = """examples:
  tokenring log info logs/drive.trlog
  tokenring log info logs/drive.trerr --json
  tokenring log info logs/broken.trlog --salvage                    # count around damage inside
"""
EXAMPLES = """examples:
  tokenring log convert logs/drive.trlog --to csv --out drive-csv/
  tokenring log sort logs/drive.trlog --out sorted.trlog
  tokenring log info logs/drive.trlog
  tokenring log convert --help                                      # each verb's own examples
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_json_option, with_examples

    p = sub.add_parser(
        "log",
        **with_examples(EXAMPLES),
        help=HELP,
        description="Data and error logs are msgpack streams (crash-safe, compact). 'convert' writes the "
        "seed's line-per-entry text (--to text; --to seed: exactly the seed's appendix B line "
        "formats) or, for a data log, one line per synchronisation: exactly the seed's logfileconverter's "
        "data.dat and sonar.dat (--to dat, table B.8) or data.csv and sonar.csv with our own columns "
        "(--to csv), or MCAP for Foxglove and PlotJuggler (--to mcap); "
        "'sort' orders a log by time stamp "
        "into a new file (the seed's logfilesorter); 'info' counts records per source and kind.",
    )
    verbs = p.add_subparsers(dest="log_verb", metavar="VERB", required=True)
    convert = verbs.add_parser(
        "convert",
        help="to the seed's text, table B.8's data.dat/sonar.dat, CSV or MCAP",
        **with_examples(CONVERT_EXAMPLES),
    )
    convert.add_argument("log", help="a data (.trlog) or error (.trerr) log")
    convert.add_argument(
        "--to",
        choices=("text", "seed", "dat", "csv", "mcap"),
        default="text",
        help="output format (default text; seed: the seed's exact line formats; dat: the seed's "
        "logfileconverter, table B.8's data.dat and sonar.dat)",
    )
    convert.add_argument(
        "--out",
        metavar="PATH",
        help="text, seed: a file (default: standard output); dat, csv: a directory (required); mcap: a file "
        "(required; Foxglove, PlotJuggler)",
    )
    convert.add_argument("--force", action="store_true", help="replace an existing output")
    order = verbs.add_parser("sort", help="sort by time stamp into a new log", **with_examples(SORT_EXAMPLES))
    order.add_argument("log")
    order.add_argument("--out", required=True, metavar="FILE", help="the sorted log (a new file)")
    order.add_argument("--force", action="store_true", help="replace an existing output (never the input)")
    info = verbs.add_parser(
        "info",
        help="header, time range, counts per source and kind, torn tail",
        **with_examples(INFO_EXAMPLES),
    )
    info.add_argument("log")
    add_json_option(info)
    for verb in (convert, order, info):
        verb.add_argument(
            "--salvage",
            action="store_true",
            help="read the records around damage inside the log (else damage is an error)",
        )


#: the files each directory format writes: the data (one line per synchronisation), the sonar
DIRECTORY_OUTPUTS = {"dat": ("data.dat", "sonar.dat"), "csv": ("data.csv", "sonar.csv")}


def check_outputs(args: argparse.Namespace) -> None:
    """Before anything is read: an output is never the input, never silently replaced."""
    from pathlib import Path

    from tokenring import UsageError, check_output, option_error

    out = option_error("--out")
    if args.log_verb == "convert" and args.to == "mcap" and not args.out:
        raise UsageError("--to mcap writes one file: give it with --out FILE.mcap")
    if args.log_verb == "sort" or (
        args.log_verb == "convert" and args.to in ("text", "seed", "mcap") and args.out
    ):
        check_output(args.out, (args.log,), force=args.force, error=out)
    elif args.log_verb == "convert" and args.to in DIRECTORY_OUTPUTS:
        names = DIRECTORY_OUTPUTS[args.to]
        if not args.out:
            raise UsageError(
                f"--to {args.to} writes {names[0]} and {names[1]}: give the directory with --out"
            )
        check_output(args.out, (args.log,), directory=True, error=out)
        for name in names:
            if (Path(args.out) / name).exists():
                check_output(Path(args.out) / name, (args.log,), force=args.force, error=out)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from modules.localization.logs import (
        convert_csv,
        convert_seed_dat,
        convert_seed_text,
        convert_text,
        read_log,
        sort_log,
        summary,
    )
    from tokenring import option_error, write_atomically

    check_outputs(args)
    if args.log_verb == "sort":
        count = sort_log(args.log, args.out, salvage=args.salvage)
        print(f"{args.out}: {count} records sorted by time stamp")
        return 0
    log = read_log(args.log, salvage=args.salvage)
    if log.damaged:
        lost = sum(b - a for a, b in log.damaged)
        print(
            f"{args.log}: {lost} damaged bytes skipped in {len(log.damaged)} place(s); "
            f"{len(log.records)} records read around them",
            file=sys.stderr,
        )
    if log.truncated:
        print(f"{args.log}: the last record is torn (the writer was killed); read up to it", file=sys.stderr)
    if args.log_verb == "info":
        info = summary(log)
        if args.json:
            from tokenring.cli import print_json

            print_json(info)
        else:
            print(f"{info['file']}: {info['kind']} log started {info['start']}, {info['records']} records")
            print(
                f"time {info['first_ms']} .. {info['last_ms']} ms"
                + (" (torn tail)" if info["truncated"] else "")
            )
            for key, count in info["counts"].items():
                print(f"  {key:4} {count}")
        return 0
    if args.to == "mcap":
        from modules.pc.logmcap import convert_mcap

        counts = convert_mcap(log, args.out)
        print(f"{args.out}: {sum(counts.values())} messages on {len(counts)} topics")
        return 0
    if args.to in ("text", "seed"):
        text = convert_text(log) if args.to == "text" else convert_seed_text(log)
        if args.out:
            write_atomically(args.out, text, option_error("--out"))
            print(f"{args.out}: {len(log.records)} entries")
        else:
            sys.stdout.write(text)
        return 0
    data, sonar = convert_seed_dat(log) if args.to == "dat" else convert_csv(log)
    data_name, sonar_name = DIRECTORY_OUTPUTS[args.to]
    out = Path(args.out)
    made = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        write_atomically(out / data_name, data, None)
        write_atomically(out / sonar_name, sonar, None)
    except OSError as exc:  # a full disk: a folder this run made goes again, with what it holds
        import contextlib

        from tokenring import write_failed

        if made:
            with contextlib.suppress(OSError):
                for name in (data_name, sonar_name):
                    (out / name).unlink(missing_ok=True)
                out.rmdir()
        raise write_failed(out, exc, option_error("--out")) from None
    syncs = data.count("\n") - (1 if args.to == "csv" else 0)  # data.csv has a header line
    print(f"{out}/{data_name}: {syncs} synchronisations; {out}/{sonar_name}")
    return 0
