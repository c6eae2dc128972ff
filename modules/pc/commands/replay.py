"""``tokenring replay``: the offline mode — run the synchronisation and the filter again on a log."""

from __future__ import annotations

import argparse
import os
import sys

HELP = "run the synchronisation and EKF again on a recorded data log (offline mode)"

EXAMPLES = """examples:
  tokenring replay logs/drive.trlog --out again.trlog --check      # bit for bit as online
  tokenring replay logs/drive.trlog --out sync.trlog --from sync
  tokenring replay logs/drive.trlog --out tuned.trlog --config config/localization.yaml
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_json_option, with_examples

    p = sub.add_parser(
        "replay",
        **with_examples(EXAMPLES),
        help=HELP,
        description="Replay a data log as if its samples came from the sensors (--from raw, the default: "
        "every synchronisation again on exactly the samples it had online) or feed its synchronised "
        "records to the filter (--from sync). With the log's own configuration the positions equal "
        "the online ones bit for bit (--check says so); --config tries other settings on the same run.",
    )
    p.add_argument("log", help="data log to replay (.trlog)")
    p.add_argument("--out", required=True, metavar="FILE", help="the new data log to write")
    p.add_argument(
        "--config",
        metavar="FILE",
        help="settings, YAML or the seed's .cfg (default: the configuration recorded in the log)",
    )
    p.add_argument(
        "--from",
        dest="mode",
        choices=("raw", "sync", "retrigger"),
        default="raw",
        help="raw samples at the logged sync points, synchronised records, or raw samples through the "
        "config's trigger (default %(default)s)",
    )
    p.add_argument("--errors", metavar="FILE", help="also write an error log")
    p.add_argument("--force", action="store_true", help="replace an existing --out or --errors file")
    p.add_argument(
        "--salvage",
        action="store_true",
        help="read the records around damage inside the log (else damage is an error)",
    )
    p.add_argument("--check", action="store_true", help="exit 1 unless the positions equal the input log's")
    add_json_option(p)


def run(args: argparse.Namespace) -> int:
    from modules.localization.config import seed_notes
    from modules.pc.replay import replay
    from tokenring.cli import print_json

    check_outputs(args)

    def progress(done: int, total: int) -> None:
        if sys.stderr.isatty():
            print(f"\rreplaying {done}/{total} records", end="", file=sys.stderr, flush=True)

    with seed_notes(quiet=args.json):  # a seed file's values that do not apply here, on stderr
        result = replay(
            args.log,
            args.out,
            args.config,
            mode=args.mode,
            errors=args.errors,
            progress=progress,
            salvage=args.salvage,
        )
    if sys.stderr.isatty():
        print(file=sys.stderr)
    if args.json:
        print_json(
            {
                "output": str(result.output),
                "syncs": result.syncs,
                "positions": result.positions,
                "compared": result.compared,
                "identical": result.identical,
                "first_difference": result.first_difference,
                "report": result.report,
            }
        )
    else:
        print(f"{result.output}: {result.syncs} synchronisations, {result.positions} positions")
        if result.identical:
            print(f"identical to the input log ({result.compared} positions compared)")
        else:
            print(f"differs from the input log: {result.first_difference}")
        pose = result.report.get("pose", {})
        if pose:
            print(
                f"final pose ({pose['source']}): x {pose['x_mm']:.1f} mm, y {pose['y_mm']:.1f} mm, "
                f"heading {pose['heading_deg']:.2f}°"
            )
    return 1 if args.check and not result.identical else 0


def check_outputs(args: argparse.Namespace) -> None:
    """Before the log is read: neither output is the input or the other output, nor an existing
    file without ``--force``, and both folders are writable."""
    from tokenring import UsageError, check_output, option_error

    check_output(args.out, (args.log,), force=args.force, error=option_error("--out"))
    if args.errors:
        check_output(args.errors, (args.log,), force=args.force, error=option_error("--errors"))
        if os.path.abspath(args.errors) == os.path.abspath(args.out):
            raise UsageError(
                f"--errors {args.errors}: is the --out file too; give the error log its own path"
            )
