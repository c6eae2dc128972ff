"""A pcapng capture of a ring's frames beside other work: ``record --pcap``'s (a Zenoh session of
its own) and the watcher's (``watch --pcap``, ``up --pcap``: the watcher's own feed, no second
subscription to the frames). Helpers of the verbs, not a verb."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from typing import TYPE_CHECKING, Any

from tokenring.errors import UsageError

if TYPE_CHECKING:
    from collections.abc import Iterator

    from tokenring.observe.pcapng import PcapngWriter


def check_pcap_output(
    option: str, path: str, force: bool, other: str | None = None, other_option: str = "--record"
) -> None:
    """Refuse a capture path before anything starts: a ``.pcap`` name (the file is pcapng), the
    same file as ``other`` (the MCAP recording, given as ``other_option``), an existing file
    without ``force``."""
    from tokenring.cli.output import check_option_output

    if path.lower().endswith(".pcap"):
        raise UsageError(f"{option} {path}: the capture is written as pcapng: name it .pcapng")
    if other is not None and os.path.abspath(other) == os.path.abspath(path):
        raise UsageError(f"{option} {path}: is {other_option} too; give the capture another name")
    check_option_output(option, path, force=force)


class PcapCapture:
    """``--pcap``: every frame into a pcapng file, from a feed of the token's keys alone."""

    def __init__(self, writer: PcapngWriter, feed: Any, verb: str) -> None:
        self.writer = writer
        self.feed = feed
        self.verb = verb
        self.failure_told = False
        self.seconds = 0.0

    def on_raw(self, raw: Any) -> None:
        """The feed's raw sink: the frame into the file; a failure said once, as it happens."""
        self.writer.on_raw(raw)
        self.tell_failure()

    def tell_failure(self) -> bool:
        if self.writer.failure is None:
            return False
        if not self.failure_told:
            self.failure_told = True
            print(f"tokenring {self.verb}: error: {self.writer.failure}", file=sys.stderr, flush=True)
        return True

    def summary(self) -> dict[str, Any]:
        path = self.writer.path
        return {
            "file": str(path),
            "frames": self.writer.frames_kept,
            "bytes": path.stat().st_size if path.exists() else 0,
            "failure": self.writer.failure,
            "dropped": self.feed.dropped,
        }

    def line(self) -> str:
        s = self.summary()
        dropped = f"; {s['dropped']} frames dropped (the capture fell behind)" if s["dropped"] else ""
        return f"{s['file']}: {s['frames']} frames, {s['bytes'] / 1e6:.1f} MB (pcapng){dropped}"


@contextlib.contextmanager
def pcap_capture(args: argparse.Namespace, ring: str) -> Iterator[PcapCapture | None]:
    """``--pcap``'s capture while the block runs (None without ``--pcap``): on a Zenoh session of
    its own, opened first (a refused endpoint leaves no file). It is finished as ``FILE`` when the
    block ends; a block that fails before a frame came leaves no file."""
    if args.pcap is None:
        yield None
        return
    from tokenring.cli.args import protocol_text, tap_session
    from tokenring.contract.protocol import load_protocol
    from tokenring.observe.feed import Feed
    from tokenring.observe.pcapng import PcapngWriter, TokenFrames

    protocol = load_protocol(args.protocol)
    text = protocol_text(args.protocol)
    with tap_session(args) as session:
        writer = PcapngWriter(args.pcap, ring=ring, protocol=protocol, protocol_text=text)
        feed = Feed(session, ring, [TokenFrames()])
        capture = PcapCapture(writer, feed, getattr(args, "command", None) or "record")
        feed.add_raw_sink(capture.on_raw)
        started = time.monotonic()
        finished = False
        try:
            feed.start()
            yield capture
            finished = True
        finally:
            feed.stop()
            capture.seconds = time.monotonic() - started
            if finished or writer.frames:
                writer.close()
                capture.tell_failure()
            else:
                writer.discard()
