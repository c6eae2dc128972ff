"""``tokenring play FILE.mcap``: put a recording's frames and samples back on Zenoh, in time.

``sniff`` and the web view then see them as if the ring were live, and ``monitor`` the nodes'
counters and faults as recorded (play answers its queries and holds the nodes' liveliness). The
samples go back on the keys they were recorded on (the recorded ring's name) unless ``--ring``
names another. Playing into a ring that is running under that name would inject old frames into
it, so play refuses when it finds the ring's nodes live.

Play never drops a frame for a slow reader: it waits on a subscriber that reads slower than it
sends (up to ``--slow-wait``), and before it closes it asks every ``sniff`` whether the last frame
has reached it. Exit code 1 if one did not answer in time, or if Zenoh cut a sniff's link while
playing (its liveliness token went without its goodbye: the frames queued towards it are lost).
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from tokenring.cli.args import add_ring_options, non_negative_seconds, seconds, with_examples

HELP = "replay an MCAP recording onto Zenoh, in time, as if the ring were live"

EXAMPLES = """examples:
  tokenring play run.mcap --listen tcp/127.0.0.1:7447     # then: tokenring sniff --ring <recorded>
  tokenring play run.mcap --rate 4 --start 20 --duration 10
  tokenring play run.mcap --topics 'token/*' --loop -e tcp/127.0.0.1:7447
  tokenring play run.mcap --ring replay --listen tcp/127.0.0.1:7450 --json
"""


def rate(text: str) -> float:
    """An argparse type: a speed factor above 0 and at most 1000."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < value <= 1000:
        raise argparse.ArgumentTypeError(f"{text}: give a factor above 0 and at most 1000")
    return value


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "play",
        help=HELP,
        description=__doc__,
        **with_examples(EXAMPLES),
    )
    p.add_argument(
        "file", metavar="FILE.mcap", help="a recording (tokenring record, up --record, sniff --write)"
    )
    p.add_argument(
        "--rate", type=rate, default=1.0, metavar="K", help="K times the recorded pace (default 1)"
    )
    p.add_argument(
        "--start",
        type=non_negative_seconds,
        default=0.0,
        metavar="S",
        help="begin S seconds into the recording",
    )
    p.add_argument("--duration", type=seconds, metavar="S", help="play S seconds of the recording")
    p.add_argument(
        "--topics",
        metavar="GLOBS",
        help="comma-separated globs of the Zenoh keys to play, whole or inside the ring (token/*, "
        "world/*); default every recorded key",
    )
    p.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    p.add_argument(
        "--wait",
        type=non_negative_seconds,
        default=5.0,
        metavar="S",
        help="wait up to S seconds for a subscriber (sniff, the web view) before playing (default 5)",
    )
    p.add_argument(
        "--slow-wait",
        type=seconds,
        default=60.0,
        metavar="S",
        help="wait up to S seconds on a subscriber that reads slower than play sends, and at the "
        "end for every sniff to have taken the last frame (default 60; Zenoh drops a link blocked "
        "for 5 s, which lost frames to a sniff on a loaded machine)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.add_argument("--json", action="store_true", help="print a JSON summary at the end")
    add_ring_options(p)
    p.set_defaults(ring=None)  # default: the ring name the file was recorded from


def ring_is_live(session: object, ring: str) -> bool:
    """Whether nodes of ``ring`` hold their liveliness tokens on this Zenoh network."""
    from tokenring.contract import keys

    try:
        replies = session.liveliness().get(keys.node(ring, "*"), timeout=1.0)  # type: ignore[attr-defined]
        return any(reply.ok is not None for reply in replies)
    except Exception:
        return False


def run(args: argparse.Namespace) -> int:
    from tokenring.cli.args import tap_session
    from tokenring.cli.output import print_json
    from tokenring.contract import keys
    from tokenring.errors import UsageError
    from tokenring.observe.recording import Player, Selection, Stopper, open_recording

    recording = open_recording(args.file)
    selection = Selection.parse(args.topics)
    ring = args.ring or recording.ring or keys.DEFAULT_RING
    if not recording.raw_keys():
        raise UsageError(f"{args.file}: no raw samples recorded (recorded with --topics?); nothing to play")
    if args.start >= recording.duration_s and recording.duration_s > 0:
        raise UsageError(f"--start {args.start:g}: the recording lasts {recording.duration_s:.1f} s")
    if not args.connect and not args.listen:
        args.connect = [keys.default_endpoint()]
    stopper = Stopper()
    stopper.install()
    with tap_session(args, block_close_s=args.slow_wait) as session:
        if ring_is_live(session, ring):
            raise UsageError(
                f"ring {ring!r} is running on this network: playing would inject old frames into it; "
                "give another --ring"
            )
        player = Player(
            session,
            recording,
            rate=args.rate,
            start_s=args.start,
            duration_s=args.duration,
            selection=selection,
            ring=ring,
        )
        if not player.keys:
            raise UsageError(f"--topics {args.topics}: matches none of the recorded keys")
        player.declare()
        player.watch_taps()
        player.serve_control()  # monitor sees the recorded nodes' counters
        if not args.quiet:
            print(
                f"playing {args.file} ({recording.duration_s:.1f} s, ring {recording.ring!r}) as ring {ring!r} "
                f"at {args.rate:g}x",
                file=sys.stderr,
                flush=True,
            )
        if args.wait > 0 and not player.wait_subscribers(args.wait, stopper.event) and not args.quiet:
            print(f"nobody subscribed within {args.wait:g} s; playing anyway", file=sys.stderr, flush=True)
        progress = sys.stderr.isatty() and not args.quiet
        started = time.monotonic()
        shown = [0.0]

        def show(_: object) -> None:
            now = time.monotonic()
            if progress and now - shown[0] >= 0.5:
                shown[0] = now
                sys.stderr.write(
                    f"\r{player.stats.recorded_s:7.1f} s of {recording.duration_s:.1f}  "
                    f"{player.stats.frames} frames  {player.stats.samples} samples "
                )
                sys.stderr.flush()

        taps, unconfirmed, lost = 0, False, []
        try:
            while not stopper.event.is_set():
                player.play_once(stopper.event, show)
                player.stats.loops += 1
                if not args.loop:
                    break
            if not stopper.event.is_set():
                taps, ran_out = player.wait_drained(args.slow_wait, stopper.event)
                unconfirmed = ran_out and not stopper.event.is_set()
                if unconfirmed:
                    print(
                        f"a tap had not taken every frame within {args.slow_wait:g} s (--slow-wait); "
                        "what was still queued towards it is lost",
                        file=sys.stderr,
                        flush=True,
                    )
                lost = player.taps_lost()
                if lost and not unconfirmed:
                    print(
                        f"Zenoh cut the link to {len(lost)} tap(s) while playing ({', '.join(lost)}: "
                        f"stalled past --slow-wait {args.slow_wait:g} s or past its lease); the frames "
                        "queued towards it were dropped",
                        file=sys.stderr,
                        flush=True,
                    )
            time.sleep(0.2)  # let the last samples leave before the session closes
        finally:
            player.close()
        if progress:
            sys.stderr.write("\n")
    summary = {
        "file": str(recording.path),
        "ring": ring,
        "recorded_ring": recording.ring,
        "samples": player.stats.samples,
        "frames": player.stats.frames,
        "loops": player.stats.loops,
        "taps_drained": taps,  # sniffs that confirmed every frame before play closed
        "taps_lost": lost,  # sniffs cut off while playing: frames towards them were dropped
        "seconds": round(time.monotonic() - started, 3),
    }
    if args.json:
        print_json(summary)
    elif not args.quiet:
        print(
            f"played {summary['samples']} samples ({summary['frames']} frames) in {summary['seconds']:.1f} s"
        )
    if stopper.signal == signal.SIGINT:
        return 130
    return 1 if unconfirmed or lost else 0
