"""One watcher of a running ring: the web view, an MCAP recording, the Foxglove bridge, the
Prometheus metrics and a pcapng capture on one feed (:mod:`tokenring.observe.feed`), as
``tokenring watch`` runs it and ``web``, ``record`` and ``foxglove`` run one part of it. Apart
from the verbs, which import it only when they run."""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tokenring.cli.pcapcapture import PcapCapture
    from tokenring.observe.foxglove import FoxgloveBridge
    from tokenring.observe.metrics import RingMetrics
    from tokenring.observe.recording import McapRecorder, Stopper


@dataclass
class Watch:
    """What one watcher serves and records; filled in as it starts (URLs) and runs (sinks)."""

    ring: str
    web_port: int | None = None  # None: no web view
    record: str | None = None
    foxglove_port: int | None = None
    host: str = "127.0.0.1"
    duration: float | None = None
    ready_token: str | None = None
    topics: str | None = None
    compression: str = "zstd"
    metrics_port: int | None = None  # None: no Prometheus metrics
    metrics_host: str = "127.0.0.1"
    pcap: str | None = None  # every frame to this pcapng file (Wireshark); None: none
    #: what runs while it serves (the recorder's progress line), every half second
    on_tick: Callable[[Watch, float], None] | None = None
    #: called once everything serves and records
    on_ready: Callable[[Watch], None] | None = None
    web_url: str | None = None
    foxglove_url: str | None = None
    metrics_url: str | None = None
    recorder: McapRecorder | None = None
    bridge: FoxgloveBridge | None = None
    metrics: RingMetrics | None = None
    capture: PcapCapture | None = None
    dropped: int = 0
    elapsed: float = 0.0
    failure_told: bool = False  # the recording's failure was said
    stopper: Stopper | None = None
    #: the options that name the recording and the ports, in messages about them
    record_option: str = "--record"
    web_port_option: str = "--web-port"
    foxglove_port_option: str = "--foxglove-port"
    metrics_option: str = "--metrics"
    pcap_option: str = "--pcap"


def serve(args: argparse.Namespace, watch: Watch) -> int:
    """Run ``watch`` on a ring until Ctrl-C, SIGTERM or its duration; 130 after Ctrl-C, 1 if the
    recording failed (a full disk), else 0.

    Everything that can be refused (the output file, a port in use) is refused before the
    process joins the ring; the recording is finalised before the feed stops. A recording that
    cannot be written is named in one line as it fails; the web view and the Foxglove bridge
    go on without it, and a watcher that only recorded stops."""
    from tokenring import extensions
    from tokenring.cli.args import protocol_text, tap_session
    from tokenring.cli.output import check_option_output
    from tokenring.contract import keys
    from tokenring.contract.protocol import load_protocol
    from tokenring.errors import UsageError
    from tokenring.observe.feed import Feed, FeedSource, RingSource, feed_sources
    from tokenring.observe.recording import McapRecorder, Selection, Stopper

    if (
        watch.web_port is None
        and watch.record is None
        and watch.foxglove_port is None
        and watch.metrics_port is None
        and watch.pcap is None
    ):
        raise UsageError(
            "give at least one of --web, --record FILE.mcap, --foxglove, --metrics PORT, --pcap FILE.pcapng"
        )
    if not watch.host.strip():
        raise UsageError("--host: give an address to serve on, e.g. 127.0.0.1")
    if watch.metrics_port is not None and not watch.metrics_host.strip():
        raise UsageError("--metrics-host: give an address to serve on, e.g. 127.0.0.1")
    if watch.record is not None:
        check_option_output(watch.record_option, watch.record, force=getattr(args, "force", False))
    if watch.pcap is not None:
        from tokenring.cli.pcapcapture import check_pcap_output

        check_pcap_output(
            watch.pcap_option,
            watch.pcap,
            getattr(args, "force", False),
            other=watch.record,
            other_option=watch.record_option,
        )
    selection = Selection.parse(watch.topics)
    # the keyboard's options (files its keys run) are refused before the process joins the ring
    web_keys = extensions.web_keys(args) if watch.web_port is not None else None
    protocol = load_protocol(args.protocol)
    # only counted (metrics) or captured (pcap): the robot's topics and the channels go unread,
    # and the nodes are asked for their counters only when Prometheus scrapes
    if watch.web_port is None and watch.record is None and watch.foxglove_port is None:
        sources: list[FeedSource] = [RingSource(protocol, poll_interval_s=0.0, channels_decoded=False)]
    else:
        sources = feed_sources(protocol, watch.ring)
    if watch.foxglove_port is not None:
        from tokenring.observe.foxglove import FoxgloveBridge

        topics = Feed(None, watch.ring, sources).topics()
        # the server first: a port in use is refused before anything joins the ring
        watch.bridge = FoxgloveBridge(
            topics,
            host=watch.host,
            port=watch.foxglove_port,
            name=f"tokenring {watch.ring}",
            port_option=watch.foxglove_port_option,
        )
        host = f"[{watch.host}]" if ":" in watch.host else watch.host
        watch.foxglove_url = f"ws://{host}:{watch.bridge.port}"
    watch.stopper = stopper = Stopper()
    stopper.install()
    started = time.monotonic()
    try:
        if watch.metrics_port is not None:
            from tokenring.observe.metrics import RingMetrics

            # served before the process joins the ring: a port in use is refused first
            watch.metrics = RingMetrics(watch.ring)
            watch.metrics_url = watch.metrics.serve(
                watch.metrics_host, watch.metrics_port, option=watch.metrics_option
            )
        with tap_session(args) as session:
            feed = Feed(session, watch.ring, sources)
            if watch.metrics is not None:
                watch.metrics.ask_on_scrape(session)
                feed.add_sink(watch.metrics.on_message)
                watch.metrics.dropped = lambda: feed.dropped
            if watch.record is not None:
                watch.recorder = McapRecorder(
                    watch.record,
                    ring=watch.ring,
                    topics=feed.topics(),
                    protocol_text=protocol_text(args.protocol),
                    selection=selection,
                    compression=watch.compression,
                )
                feed.add_sink(watch.recorder.on_message)
                feed.add_raw_sink(watch.recorder.on_raw)
            if watch.pcap is not None:
                from tokenring.cli.pcapcapture import PcapCapture
                from tokenring.observe.pcapng import PcapngWriter

                writer = PcapngWriter(
                    watch.pcap, ring=watch.ring, protocol=protocol, protocol_text=protocol_text(args.protocol)
                )
                capture = watch.capture = PcapCapture(writer, feed, getattr(args, "command", None) or "watch")
                feed.add_raw_sink(lambda raw: capture.on_raw(raw) if is_frame_key(raw.key) else None)
            if watch.bridge is not None:
                feed.add_sink(watch.bridge)
            view = None
            if watch.web_port is not None:
                from tokenring.web.server import WebView

                view = WebView(
                    session,
                    watch.ring,
                    protocol,
                    sources,
                    panels=extensions.web_panels(),
                    actions=extensions.web_actions(),
                    keys=web_keys,
                    feed=feed,
                )
            token = None
            served = False

            def ready() -> None:
                nonlocal token, served
                served = True
                if watch.ready_token:
                    token = session.liveliness().declare_token(
                        keys.watch_ready(watch.ring, watch.ready_token)
                    )
                if watch.on_ready is not None:
                    watch.on_ready(watch)
                sys.stdout.flush()

            def tick() -> bool:
                """Every half second: flush the recording, report; True once it is time to stop."""
                elapsed = time.monotonic() - started
                writing = []  # whether each file still writes
                if watch.recorder is not None:
                    watch.recorder.tick()
                    writing.append(not recording_failed(args, watch))
                if watch.capture is not None:
                    watch.capture.writer.tick()
                    writing.append(not watch.capture.tell_failure())
                serving = view is not None or watch.bridge is not None or watch.metrics is not None
                if writing and not any(writing) and not serving:
                    return True  # it only wrote files, and none can be written: nothing left to do
                if watch.on_tick is not None:
                    watch.on_tick(watch, elapsed)
                return stopper.event.is_set() or (watch.duration is not None and elapsed >= watch.duration)

            try:
                feed.start()
                if view is None:
                    ready()
                    while not stopper.event.wait(0.5):
                        if tick():
                            break
                else:
                    asyncio.run(_serve_web(view, watch, ready, tick))
            finally:
                if watch.recorder is not None and not served:
                    watch.recorder.discard()  # it never ran (a port in use): no file, FILE untouched
                elif watch.recorder is not None:
                    watch.recorder.close()  # the file first: a launcher stopping us waits only a moment
                    recording_failed(args, watch)
                if watch.capture is not None and not served:
                    watch.capture.writer.discard()
                elif watch.capture is not None:
                    watch.capture.writer.close()
                    watch.capture.tell_failure()
                feed.stop()
                watch.dropped = feed.dropped
                if token is not None:
                    token.undeclare()
    finally:
        if watch.metrics is not None:
            watch.metrics.close()
        if watch.bridge is not None:
            watch.bridge.close()
    watch.elapsed = time.monotonic() - started
    if stopper.signal == signal.SIGINT:
        return 130
    failed = (watch.recorder is not None and watch.recorder.failure) or (
        watch.capture is not None and watch.capture.writer.failure
    )
    return 1 if failed else 0


def is_frame_key(key: str) -> bool:
    """A token frame's key (``tokenring/<ring>/token/<id>``), not an event's or a channel's."""
    parts = key.rsplit("/", 2)
    return len(parts) == 3 and parts[1] == "token"


def recording_failed(args: argparse.Namespace, watch: Watch) -> bool:
    """Whether the recording failed; the first time, its one line on stderr."""
    recorder = watch.recorder
    if recorder is None or recorder.failure is None:
        return False
    if not watch.failure_told:
        watch.failure_told = True
        verb = getattr(args, "command", None) or "watch"
        print(f"tokenring {verb}: error: {recorder.failure}", file=sys.stderr, flush=True)
    return True


async def _serve_web(view: Any, watch: Watch, ready: Callable[[], None], tick: Callable[[], bool]) -> None:
    stop = asyncio.Event()

    def served(url: str) -> None:
        watch.web_url = url
        ready()

    async def ticker() -> None:
        while not tick():
            await asyncio.sleep(0.5)
        stop.set()

    ticking = asyncio.create_task(ticker())
    try:
        await view.serve(watch.host, watch.web_port, served, stop, port_option=watch.web_port_option)
    finally:
        ticking.cancel()


def recording_summary(watch: Watch) -> dict[str, Any]:
    """The recording's figures once it is closed (file, frames, messages, channels, bytes)."""
    recorder = watch.recorder
    assert recorder is not None
    frames = sum(n for k, n in recorder.counts.items() if "/token/" in k)
    return {
        "file": str(recorder.path),
        "ring": watch.ring,
        "seconds": round(watch.elapsed, 3),
        "messages": recorder.messages_kept,
        "frames": frames,
        "bytes": recorder.path.stat().st_size if recorder.path.exists() else 0,
        "failure": recorder.failure,
        "dropped": watch.dropped,
        "counts": dict(sorted(recorder.counts.items())),
    }


def record_progress(watch: Watch, elapsed: float) -> None:
    """The recording's one-line progress on a terminal's stderr."""
    recorder = watch.recorder
    if recorder is None:
        return
    frames = sum(n for k, n in recorder.counts.items() if "/token/" in k)
    sys.stderr.write(
        f"\r{elapsed:6.1f} s  {frames} frames  {recorder.messages} messages "
        f"on {len(recorder.counts)} channels  {recorder.raw_bytes / 1e6:.1f} MB raw "
    )
    sys.stderr.flush()
