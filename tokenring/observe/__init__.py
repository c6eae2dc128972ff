"""Taps: they read a running ring and never write to the token. The feed of named topics (what
record, play, the web view and Foxglove read), MCAP recordings, sniffing, captures of the wire."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring.observe.capture import CapturedFrames, first_full_round, passes, settled
    from tokenring.observe.feed import (
        Feed,
        FeedSource,
        Message,
        RingSource,
        Topic,
        decode_msgpack,
        feed_sources,
    )
    from tokenring.observe.pcap_tap import WireTap, WireTapError, tcpdump_path
    from tokenring.observe.recording import McapRecorder
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "CapturedFrames": "tokenring.observe.capture",
            "decode_msgpack": "tokenring.observe.feed",
            "Feed": "tokenring.observe.feed",
            "feed_sources": "tokenring.observe.feed",
            "FeedSource": "tokenring.observe.feed",
            "first_full_round": "tokenring.observe.capture",
            "McapRecorder": "tokenring.observe.recording",
            "Message": "tokenring.observe.feed",
            "passes": "tokenring.observe.capture",
            "RingSource": "tokenring.observe.feed",
            "settled": "tokenring.observe.capture",
            "tcpdump_path": "tokenring.observe.pcap_tap",
            "Topic": "tokenring.observe.feed",
            "WireTap": "tokenring.observe.pcap_tap",
            "WireTapError": "tokenring.observe.pcap_tap",
        },
    )

__all__ = [
    "CapturedFrames",
    "Feed",
    "FeedSource",
    "McapRecorder",
    "Message",
    "RingSource",
    "Topic",
    "WireTap",
    "WireTapError",
    "decode_msgpack",
    "feed_sources",
    "first_full_round",
    "passes",
    "settled",
    "tcpdump_path",
]
