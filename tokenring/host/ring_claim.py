"""Whether a launcher may run its ring here: a ring runs once per Zenoh network, and a node ID
joins it once (two nodes under one ID would both take its token).

Before it starts anything, a launcher asks every launcher of its ring for its status and looks
at which of the ring's node IDs are live; it refuses, naming the holder, a ring that an older
launcher holds or IDs that are live there."""

from __future__ import annotations

import contextlib
import os
import socket
from collections.abc import Collection, Mapping
from typing import Any

import msgpack
import zenoh

from tokenring.contract import keys
from tokenring.errors import TransportError, UsageError
from tokenring.transport.zenoh import ring_view

#: how long a launcher asks who holds its ring before it starts anything (answers end it early)
RING_CHECK_TIMEOUT_S = 2.0


def describe_holder(status: Mapping[str, Any]) -> str:
    """'the launcher pid 123 on host h (tcp/127.0.0.1:7447, nodes 10, 20)', from its status."""
    running = [str(n.get("id")) for n in status.get("nodes", ()) if n.get("running")]
    where = [status["endpoint"]] if status.get("endpoint") else []
    if running:
        where.append(f"nodes {', '.join(running)}")
    detail = f" ({', '.join(where)})" if where else ""
    return f"the launcher pid {status.get('pid', '?')} on host {status.get('host', '?')}{detail}"


def launchers_of_the_ring(session: zenoh.Session, ring: str) -> list[dict[str, Any]]:
    """Every launcher's status answer on ``ring`` (the asking launcher's own too)."""
    answers = []
    try:
        replies = session.get(
            keys.control(ring, "launcher", "status"),
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
            timeout=RING_CHECK_TIMEOUT_S,
        )
        for reply in replies:
            if reply.ok is None:
                continue
            with contextlib.suppress(ValueError, TypeError, msgpack.ExtraData):
                answer = msgpack.unpackb(reply.ok.payload.to_bytes())
                if isinstance(answer, dict) and isinstance(answer.get("result"), dict):
                    answers.append(answer["result"])
    except zenoh.ZError as exc:
        raise TransportError(f"asking who holds ring {ring!r} failed: {exc}") from exc
    return answers


def live_node_ids(session: zenoh.Session, ring: str) -> set[int]:
    """The ring's node IDs live on this network: liveliness (through a router) and a peer
    ring's own view (a peer answers liveliness queries only for itself)."""
    ids: set[int] = set()
    with contextlib.suppress(zenoh.ZError):
        for reply in session.liveliness().get(keys.node(ring, "*"), timeout=RING_CHECK_TIMEOUT_S):
            if reply.ok is not None:
                node_id = keys.id_from_key(str(reply.ok.key_expr))
                if node_id is not None:
                    ids.add(node_id)
        ids |= ring_view(session, ring)
    return ids


def refuse_a_ring_in_use(
    session: zenoh.Session,
    ring: str,
    *,
    instance: str,
    started_at: float,
    node_ids: Collection[int],
    joining: bool,
    zenoh_membership: bool = True,
) -> None:
    """Raise :class:`UsageError` for a ring another launcher holds on this Zenoh network, naming
    it; and always for IDs that are live there.

    ``joining`` (``--connect``) joins a ring on purpose (one launcher per host, docs/hosts.md):
    then only live IDs are refused. Two launchers that start at once both see each other; the
    younger refuses (by start time, then host and PID). ``instance`` is the asking launcher's
    own, so that its own status answer does not count."""
    holders = [h for h in launchers_of_the_ring(session, ring) if h.get("instance") != instance]
    live = {int(n["id"]) for h in holders for n in h.get("nodes", ()) if n.get("running")}
    if zenoh_membership:  # udp/zmq rings keep their membership in the launcher's registry
        live |= live_node_ids(session, ring)
    held_by = "; ".join(describe_holder(h) for h in holders)
    taken = sorted(set(node_ids) & live)
    if taken:
        raise UsageError(
            f"ring {ring!r} is in use: node ID(s) {', '.join(map(str, taken))} live there"
            + (f", held by {held_by}" if held_by else "")
            + "; an ID joins a ring once: pick another --ring, or --nodes not live there"
        )
    me = (started_at, socket.gethostname(), os.getpid())
    older = [h for h in holders if (h.get("started", 0.0), h.get("host", ""), h.get("pid", 0)) < me]
    if older and not joining:
        raise UsageError(
            f"ring {ring!r} is in use on this Zenoh network, held by "
            + "; ".join(describe_holder(h) for h in older)
            + ": pick another --ring (or join it on purpose: --connect ENDPOINT and --nodes it does not run)"
        )
