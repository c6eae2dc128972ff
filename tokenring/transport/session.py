"""A tool's talk with a running ring over Zenoh: who is live, control queries, a free port."""

from __future__ import annotations

import random
import socket
import time
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

import msgpack
import zenoh

from tokenring.contract import keys
from tokenring.errors import TransportError, UsageError
from tokenring.transport.zenoh_config import unanswered_hint


def discover(session: zenoh.Session, ring: str, timeout: float = 5.0, settle: float = 0.5) -> set[int]:
    """IDs of the ring's live nodes as seen from a fresh tool session.

    Peers do not route for each other: a new session reaches a node only once gossip has
    connected it to that node, which takes a moment. Wait until the set of liveliness tokens
    seen is non-empty and has not changed for ``settle`` seconds (or ``timeout`` ends)."""
    deadline = time.monotonic() + timeout
    seen: set[int] = set()
    stable_since = time.monotonic()
    while time.monotonic() < deadline:
        found = set()
        try:
            for reply in session.liveliness().get(keys.node(ring, "*"), timeout=1.0):
                if reply.ok is not None:
                    node_id = keys.id_from_key(str(reply.ok.key_expr))
                    if node_id is not None:
                        found.add(node_id)
        except zenoh.ZError as exc:
            raise TransportError(f"liveliness query failed: {exc}") from exc
        if found != seen:
            seen, stable_since = found, time.monotonic()
        elif seen and time.monotonic() - stable_since >= settle:
            break
        time.sleep(0.1)
    return seen


def query(
    session: zenoh.Session,
    key: str,
    request: Any = None,
    timeout: float = 2.0,
    enough: Callable[[list[tuple[str, Any]]], bool] | None = None,
    everyone: bool = False,
) -> list[tuple[str, Any]]:
    """Query a control key; returns (key, decoded reply) for every answer.

    A key with a wildcard asks every matching node (and waits for all, up to ``timeout``, or
    until ``enough`` says the answers so far suffice: a hung node answers nothing); a plain key
    asks the best matching one only, so a hung node elsewhere cannot delay it, unless
    ``everyone`` (every launcher of a ring across hosts answers ``ctl/launcher/*``)."""
    payload = msgpack.packb(request) if request is not None else None
    out: list[tuple[str, Any]] = []
    wildcard = "*" in key or everyone
    try:
        options: dict[str, Any] = {
            "timeout": timeout,
            "target": zenoh.QueryTarget.ALL if wildcard else zenoh.QueryTarget.BEST_MATCHING,
            "consolidation": zenoh.ConsolidationMode.NONE,
        }
        if payload is not None:
            options["payload"] = payload
        replies = session.get(key, **options)
        for reply in replies:
            if reply.ok is not None:
                out.append((str(reply.ok.key_expr), msgpack.unpackb(reply.ok.payload.to_bytes())))
                if enough is not None and enough(out):
                    break
    except zenoh.ZError as exc:
        raise TransportError(f"query {key} failed: {exc}") from exc
    return out


def query_one(session: zenoh.Session, key: str, request: Any = None, timeout: float = 2.0) -> Any:
    """The result of one control request; raises if nobody answers or it failed."""
    replies = query(session, key, request, timeout)
    if not replies:
        raise UsageError(
            f"nobody answered {key} (is the ring running, and is --ring right{unanswered_hint()}?)"
        )
    _, reply = replies[0]
    if not reply.get("ok"):
        raise UsageError(reply.get("error", "request failed"))
    return reply.get("result")


def _ephemeral_ports() -> tuple[int, int]:
    """The kernel's range for outgoing connections' local ports (Linux; a common default elsewhere)."""
    try:
        low, high = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()
        return int(low), int(high)
    except (OSError, ValueError):
        return 32768, 60999


def free_port(avoid: Collection[int] = ()) -> int:
    """A TCP port on 127.0.0.1 that is free right now (tests and benchmarks), and not in ``avoid``
    (ports handed out already for listeners that have not bound yet: draws are random and repeat).

    Chosen below the ephemeral range: a port the kernel handed out (``bind(0)``) can be taken a
    moment later by any process's outgoing connection, before the listener that asked for it binds.
    """
    low, _ = _ephemeral_ports()
    candidates = range(max(1024, low - 12000), low) if low > 2048 else range(20000, 30000)
    taken = set(avoid)
    for port in random.SystemRandom().sample(candidates, min(200 + len(taken), len(candidates))):
        if port in taken:
            continue
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]
