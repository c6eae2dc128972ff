"""``tokenring record FILE.mcap``: write a running ring to an MCAP file (:mod:`tokenring.observe.recording`).

Every frame raw, every channel decoded, round trips, ring events, the nodes' counters and
faults, and every extension's topics (the robot's poses, sonar, map) with their schemas. Ctrl-C
or SIGTERM ends the recording and finalises the file; ``FILE`` appears only when it is whole.
A full disk ends it too, in one line, exit 1: what was written whole before stays ``FILE`` (a
recording without an index, as ``play`` and any MCAP reader read it), no ``FILE.part`` is left.

``--pcap FILE.pcapng`` also (or, without ``FILE.mcap``, only) writes every frame as an ARCNET
packet to a pcapng file that Wireshark and tshark open (:mod:`tokenring.observe.pcapng`;
``tokenring dissector`` decodes the token inside). It reads the frames on a Zenoh session of its
own: the MCAP recording's feed and its file are the same with it or without it.
"""

from __future__ import annotations

import argparse
import sys
import time

from tokenring.cli.args import add_ring_options, seconds, with_examples

HELP = "record a running ring to an MCAP file (Foxglove, PlotJuggler, play), its frames to pcapng (Wireshark)"

EXAMPLES = """examples:
  tokenring record run.mcap                          # until Ctrl-C
  tokenring record run.mcap --duration 60 --force    # one minute, replacing run.mcap
  tokenring record poses.mcap --topics '/robot/*'    # the robot's topics only (no raw frames)
  tokenring record run.mcap --ring lab -e tcp/10.0.0.5:7447 --json
  tokenring play run.mcap --listen tcp/127.0.0.1:7447  # and back
  tokenring record run.mcap --pcap run.pcapng        # and every frame for Wireshark
  tokenring record --pcap frames.pcapng --duration 60  # the frames for Wireshark only
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.commands.watch import add_record_options

    p = sub.add_parser(
        "record",
        help=HELP,
        description=__doc__,
        **with_examples(EXAMPLES),
    )
    p.add_argument(
        "file", metavar="FILE.mcap", nargs="?", help="the recording to write (optional with --pcap)"
    )
    p.add_argument(
        "--pcap",
        metavar="FILE.pcapng",
        help="also write every frame as an ARCNET packet to a pcapng file (Wireshark, tshark; "
        "'tokenring dissector' decodes the token inside)",
    )
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds (default: Ctrl-C)")
    add_record_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.add_argument("--json", action="store_true", help="print a JSON summary at the end")
    add_ring_options(p, listen=False)


def run(args: argparse.Namespace) -> int:
    from tokenring.cli.output import check_option_output, print_json
    from tokenring.cli.pcapcapture import check_pcap_output, pcap_capture
    from tokenring.cli.watcher import Watch, record_progress, recording_summary, serve
    from tokenring.contract import keys
    from tokenring.errors import UsageError

    ring = keys.check_ring_name(args.ring)
    progress = sys.stderr.isatty() and not args.quiet
    if args.file is None and args.pcap is None:
        raise UsageError("give the recording to write: FILE.mcap, --pcap FILE.pcapng, or both")
    if args.pcap is not None:
        if args.file is not None:
            check_option_output("FILE", args.file, force=args.force)
        check_pcap_output("--pcap", args.pcap, args.force, other=args.file, other_option="FILE")
    if args.file is None:
        return record_pcap_only(args, ring, progress)

    def announce(watch: Watch) -> None:
        if not args.quiet:
            also = f" and its frames to {args.pcap}" if args.pcap else ""
            print(
                f"recording ring {ring!r} to {args.file}{also} (Ctrl-C ends it)", file=sys.stderr, flush=True
            )

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
    with pcap_capture(args, ring) as pcap:
        code = serve(args, watch)
    summary = recording_summary(watch)
    if pcap is not None:
        summary["pcap"] = pcap.summary()
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
    if pcap is not None and not args.json and not args.quiet and not pcap.writer.failure:
        print(pcap.line())
    if not summary["messages"] and not summary["failure"] and not args.quiet:
        print(f"nothing was recorded: is ring {ring!r} running, and is --connect right?", file=sys.stderr)
    return 1 if code == 0 and pcap is not None and pcap.writer.failure else code


def record_pcap_only(args: argparse.Namespace, ring: str, progress: bool) -> int:
    """``record --pcap FILE.pcapng`` without ``FILE.mcap``: the frames only, until Ctrl-C,
    SIGTERM or ``--duration``; 130 after Ctrl-C, 1 if the capture failed (a full disk)."""
    import signal

    from tokenring.cli.output import print_json
    from tokenring.cli.pcapcapture import pcap_capture
    from tokenring.observe.recording import Stopper

    stopper = Stopper()
    stopper.install()
    with pcap_capture(args, ring) as pcap:
        assert pcap is not None
        if not args.quiet:
            print(f"capturing ring {ring!r} to {args.pcap} (Ctrl-C ends it)", file=sys.stderr, flush=True)
        started = time.monotonic()
        while not stopper.event.wait(0.5):
            pcap.writer.tick()
            if pcap.tell_failure():
                break
            elapsed = time.monotonic() - started
            if progress:
                sys.stderr.write(f"\r{elapsed:6.1f} s  {pcap.writer.frames} frames ")
                sys.stderr.flush()
            if args.duration is not None and elapsed >= args.duration:
                break
    if progress:
        sys.stderr.write("\n")
    summary = pcap.summary()
    if args.json:
        print_json({"ring": ring, "seconds": round(pcap.seconds, 3), "pcap": summary})
    elif not args.quiet and not summary["failure"]:
        print(pcap.line())
    if not summary["frames"] and not summary["failure"] and not args.quiet:
        print(f"no frame came: is ring {ring!r} running, and is --connect right?", file=sys.stderr)
    if stopper.signal == signal.SIGINT:
        return 130
    return 1 if summary["failure"] else 0
