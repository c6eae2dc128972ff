"""``tokenring record FILE.mcap``: write a running ring to an MCAP file (:mod:`tokenring.observe.recording`).

Every frame raw, every channel decoded, round trips, ring events, the nodes' counters and
faults, and every extension's topics (the robot's poses, sonar, map) with their schemas. Ctrl-C
or SIGTERM ends the recording and finalises the file; ``FILE`` appears only when it is whole.
A full disk ends it too, in one line, exit 1: what was written whole before stays ``FILE`` (a
recording without an index, as ``play`` and any MCAP reader read it), no ``FILE.part`` is left.
"""

from __future__ import annotations

import argparse
import sys

from tokenring.cli.args import add_ring_options, seconds, with_examples

HELP = "record a running ring to an MCAP file (Foxglove, PlotJuggler, tokenring play)"

EXAMPLES = """examples:
  tokenring record run.mcap                          # until Ctrl-C
  tokenring record run.mcap --duration 60 --force    # one minute, replacing run.mcap
  tokenring record poses.mcap --topics '/robot/*'    # the robot's topics only (no raw frames)
  tokenring record run.mcap --ring lab -e tcp/10.0.0.5:7447 --json
  tokenring play run.mcap --listen tcp/127.0.0.1:7447  # and back
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.commands.watch import add_record_options

    p = sub.add_parser(
        "record",
        help=HELP,
        description=__doc__,
        **with_examples(EXAMPLES),
    )
    p.add_argument("file", metavar="FILE.mcap", help="the recording to write")
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds (default: Ctrl-C)")
    add_record_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.add_argument("--json", action="store_true", help="print a JSON summary at the end")
    add_ring_options(p, listen=False)


def run(args: argparse.Namespace) -> int:
    from tokenring.cli.output import print_json
    from tokenring.cli.watcher import Watch, record_progress, recording_summary, serve
    from tokenring.contract import keys

    ring = keys.check_ring_name(args.ring)
    progress = sys.stderr.isatty() and not args.quiet

    def announce(watch: Watch) -> None:
        if not args.quiet:
            print(f"recording ring {ring!r} to {args.file} (Ctrl-C ends it)", file=sys.stderr, flush=True)

    watch = Watch(
        ring=ring,
        record=args.file,
        record_option="FILE",
        duration=args.duration,
        topics=args.topics,
        compression=args.compression,
        on_ready=announce,
        on_tick=record_progress if progress else None,
    )
    code = serve(args, watch)
    summary = recording_summary(watch)
    if progress:
        sys.stderr.write("\n")
    if args.json:
        print_json(summary)
    elif not args.quiet and not summary["failure"]:  # a failure's one line is said as it happens
        print(
            f"{summary['file']}: {summary['seconds']:.1f} s, {summary['frames']} frames, "
            f"{summary['messages']} messages on {len(summary['counts'])} channels, {summary['bytes'] / 1e6:.1f} MB"
            + (f"; {watch.dropped} samples dropped (the recorder fell behind)" if watch.dropped else "")
        )
    if not summary["messages"] and not summary["failure"] and not args.quiet:
        print(f"nothing was recorded: is ring {ring!r} running, and is --connect right?", file=sys.stderr)
    return code
