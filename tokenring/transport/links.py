"""The Zenoh transport with the token's hop on a direct link to the successor.

A node has two sessions. Its main one is a client of the host's router and carries everything
:class:`~tokenring.transport.zenoh.ZenohTransport` carries (membership, acks, ring events, the
control plane). Its link session is a Zenoh peer without gossip, listening on a port of its own
and linked to its ring successor's (the launcher assigns them: ``Launcher(links=True)``). A
frame or an ack for a node the link session reaches (a matching subscriber over a direct link:
the successor, and the predecessor, which linked to this node) goes over that link, one TCP hop
with no router between; for any other node (a pass past a dead successor, to a node that joined
later) over the router, as ``ZenohTransport`` sends it. Each put goes over one session only,
so no frame arrives twice.

Two sessions because Zenoh offers nothing simpler: a router routes for its clients, not between
peers, and a peer's links are fixed when its session opens (docs/big-rings.md, "Direct links":
a 255-process ring's tail round trip is shorter on direct links than through the router).
"""

from __future__ import annotations

from collections.abc import Callable

import zenoh

from tokenring._native import payload_call
from tokenring.contract import keys
from tokenring.transport.base import FrameHandler, FrameSender, MembershipHandler, MessageHandler
from tokenring.transport.zenoh import ZenohTransport
from tokenring.transport.zenoh_config import hop_callback


class LinkedZenohTransport(ZenohTransport):
    """:class:`ZenohTransport` on ``session`` (the router's client), the hop on ``link_session``
    (a peer linked to the successor) wherever that reaches."""

    kind = "zenoh-links"

    def __init__(
        self,
        session: zenoh.Session,
        link_session: zenoh.Session,
        ring: str,
        node_id: int,
        frame_size: int = 514,
    ):
        super().__init__(session, ring, node_id, frame_size)
        self.link_session = link_session
        self._link_senders: dict[str, FrameSender] = {}  # by key: token or ack of a node

    def _open(
        self, on_frame: FrameHandler, on_message: MessageHandler, on_membership: MembershipHandler
    ) -> set[int]:
        members = super()._open(on_frame, on_message, on_membership)
        link = self.link_session
        self._keep.append(
            link.declare_subscriber(keys.token(self.ring, self.node_id), hop_callback(payload_call(on_frame)))
        )
        self._keep.append(
            link.declare_subscriber(keys.ack(self.ring, self.node_id), payload_call(on_message))
        )
        return members

    def _either(self, key: str, via_router: Callable[[bytes | bytearray], object]) -> FrameSender:
        """A sender putting on the link session while a subscriber of ``key`` is reachable there
        (Zenoh's matching status, kept by a listener), else ``via_router``."""
        with self._pub_lock:
            publisher = self.link_session.declare_publisher(
                key,
                express=True,
                congestion_control=zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.REAL_TIME,
            )
        status: object = publisher.matching_status  # a MatchingStatus (zenoh's stub says bool)
        matched = [bool(getattr(status, "matching", status))]

        def on_matching(status: zenoh.MatchingStatus) -> None:
            matched[0] = status.matching

        # on Zenoh's own thread: a plain callable would get a Python thread of its own, and a node
        # that saw the ring form prepares a sender for each of the ~250 nodes that joined near
        # it (the first nodes of a 255-node ring held 268 threads and 40 MB against 43 and 35)
        self._keep.append(
            publisher.declare_matching_listener(zenoh.handlers.Callback(on_matching, indirect=False))
        )
        self._keep.append(publisher)
        direct = publisher.put

        def send(frame: bytes | bytearray) -> None:
            (direct if matched[0] else via_router)(frame)

        return send

    def _sender(self, did: int) -> FrameSender:
        key = keys.token(self.ring, did)
        sender = self._link_senders.get(key)
        if sender is None:
            sender = self._link_senders[key] = self._either(key, super()._sender(did))
        return sender

    def _send_message(self, did: int, payload: bytes) -> None:
        key = keys.ack(self.ring, did)
        sender = self._link_senders.get(key)
        if sender is None:
            via_router = self._publisher(did, self._message_publishers, key).put
            sender = self._link_senders[key] = self._either(key, via_router)
        sender(payload)

    def _prepare(self, did: int) -> None:
        super()._prepare(did)
        self._sender(did)
