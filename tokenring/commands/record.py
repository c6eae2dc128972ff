"""``tokenring record FILE.mcap``: write a running ring to an MCAP file (:mod:`tokenring.recording`).

Every frame raw, every channel decoded, round trips, ring events, the nodes' counters and
faults, and every extension's topics (the robot's poses, sonar, map) with their schemas. Ctrl-C
or SIGTERM ends the recording and finalises the file; ``FILE`` appears only when it is whole.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from tokenring.cliutil import add_ring_options, check_option_output, seconds, with_examples

EXAMPLES = """examples:
  tokenring record run.mcap                          # until Ctrl-C
  tokenring record run.mcap --duration 60 --force    # one minute, replacing run.mcap
  tokenring record poses.mcap --topics '/robot/*'    # the robot's topics only (no raw frames)
  tokenring record run.mcap --ring lab -e tcp/10.0.0.5:7447 --json
  tokenring play run.mcap --listen tcp/127.0.0.1:7447  # and back
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "record",
        help="record a running ring to an MCAP file (Foxglove, PlotJuggler, tokenring play)",
        description=__doc__,
        **with_examples(EXAMPLES),
    )
    p.add_argument("file", metavar="FILE.mcap", help="the recording to write")
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds (default: Ctrl-C)")
    p.add_argument("--force", action="store_true", help="replace an existing FILE")
    p.add_argument(
        "--topics",
        metavar="GLOBS",
        help="comma-separated globs of the topics (/ring/*, /channel/motor.*, /robot/*) and Zenoh keys "
        "(token/*, or whole keys) to record; default everything",
    )
    p.add_argument(
        "--compression",
        choices=("zstd", "lz4", "none"),
        default="zstd",
        help="chunk compression (default zstd)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress line")
    # `up --record`: a liveliness token tokenring/<ring>/record/<TAG> once recording (the
    # launcher waits for it before it starts the nodes, so the file holds the boot)
    p.add_argument("--ready-token", metavar="TAG", help=argparse.SUPPRESS)
    p.add_argument("--json", action="store_true", help="print a JSON summary at the end")
    add_ring_options(p, listen=False)


def protocol_text(path: str | None) -> str:
    """protocol.yaml's text as the ring reads it (the file is checked by load_protocol first)."""
    from tokenring.protocol import default_protocol_path

    return Path(path or default_protocol_path()).read_text(encoding="utf-8")


def run(args: argparse.Namespace) -> int:
    from tokenring import keys
    from tokenring.cliutil import print_json, tap_session
    from tokenring.extensions import feed_sources
    from tokenring.feed import Feed
    from tokenring.protocol import load_protocol
    from tokenring.recording import McapRecorder, Selection, Stopper

    check_option_output("FILE", args.file, force=args.force)
    protocol = load_protocol(args.protocol)
    ring = keys.check_ring_name(args.ring)
    selection = Selection.parse(args.topics)
    stopper = Stopper()
    stopper.install()
    started = time.monotonic()
    with tap_session(args) as session:
        feed = Feed(session, ring, feed_sources(protocol, ring))
        recorder = McapRecorder(
            args.file,
            ring=ring,
            topics=feed.topics(),
            protocol_text=protocol_text(args.protocol),
            selection=selection,
            compression=args.compression,
        )
        feed.add_sink(recorder.on_message)
        feed.add_raw_sink(recorder.on_raw)
        progress = sys.stderr.isatty() and not args.quiet
        if not args.quiet:
            print(f"recording ring {ring!r} to {args.file} (Ctrl-C ends it)", file=sys.stderr, flush=True)
        token = None
        try:
            feed.start()
            if args.ready_token:
                token = session.liveliness().declare_token(f"{keys.PREFIX}/{ring}/record/{args.ready_token}")
            while not stopper.event.wait(0.5):
                recorder.tick()
                elapsed = time.monotonic() - started
                if progress:
                    frames = sum(n for k, n in recorder.counts.items() if "/token/" in k)
                    sys.stderr.write(
                        f"\r{elapsed:6.1f} s  {frames} frames  {recorder.messages} messages "
                        f"on {len(recorder.counts)} channels  {recorder.raw_bytes / 1e6:.1f} MB raw "
                    )
                    sys.stderr.flush()
                if args.duration is not None and elapsed >= args.duration:
                    break
        finally:
            # the file first: a launcher stopping its services waits only a moment
            path = recorder.close()
            feed.stop()
            if token is not None:
                token.undeclare()
    elapsed = time.monotonic() - started
    frames = sum(n for k, n in recorder.counts.items() if "/token/" in k)
    size = path.stat().st_size
    summary = {
        "file": str(path),
        "ring": ring,
        "seconds": round(elapsed, 3),
        "messages": recorder.messages,
        "frames": frames,
        "bytes": size,
        "dropped": feed.dropped,
        "counts": dict(sorted(recorder.counts.items())),
    }
    if progress:
        sys.stderr.write("\n")
    if args.json:
        print_json(summary)
    elif not args.quiet:
        print(
            f"{path}: {elapsed:.1f} s, {frames} frames, {recorder.messages} messages on "
            f"{len(recorder.counts)} channels, {size / 1e6:.1f} MB"
            + (f"; {feed.dropped} samples dropped (the recorder fell behind)" if feed.dropped else "")
        )
    if not recorder.messages and not args.quiet:
        print(f"nothing was recorded: is ring {ring!r} running, and is --connect right?", file=sys.stderr)
    return 130 if stopper.signal == signal.SIGINT else 0
