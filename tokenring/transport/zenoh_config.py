"""Zenoh configuration for tokenring processes: peers on loopback, multicast scouting off.

Precedence, as in zenoh-python's examples: a config file (``--zenoh-config`` or
``$ZENOH_CONFIG``) is the base; ``--mode``, ``--connect`` and ``--listen`` override it.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable, Mapping, MutableMapping, Sequence
from typing import Any

import zenoh

from tokenring.errors import AddressInUse, TransportError, UsageError

#: Zenoh's async runtimes (RON, read by Zenoh from ``$ZENOH_RUNTIME`` when a process first uses
#: it) for a process that handles one frame at a time: one worker thread receives and sends,
#: instead of two receiving and a third sending, handing each frame to one another. Zenoh's
#: housekeeping (net, acc, app) keeps its own threads: handed over to the same worker too, a
#: node leaving the ring lost the token about once in 30 handovers (tests/ring/node/test_ring_zenoh.py,
#: the late joiner), never in 80 with them apart. ``acc`` alone handed over makes a 64-node
#: ring's hop faster but a late join then lost the token now and then, and a leave cost a
#: regeneration (the token unseen after the leaver's session closed): a speed-up that trades a
#: loss is not taken. A user's own ``$ZENOH_RUNTIME`` wins.
NODE_RUNTIME = "(rx:(worker_threads:1),tx:(handover:rx))"

#: the runtime of a process that hosts a router or many sessions (``tokenring up``, ``bench``,
#: the tools): one receiving thread, but sending on a thread of its own. On one worker that also
#: sends, a message with blocking congestion control (a query, a declaration) routed to a face
#: whose queue has no free batch waits synchronously for the tx task that would free one, which
#: needs that same worker: the router stalls until Zenoh closes that face (5 s). It did in the
#: recovery benchmark on direct links: a query to all nodes, one of them SIGSTOPped, and the
#: launcher's answer to SIGCONT never came (tests/ring/transport/test_host_runtime.py).
HOST_RUNTIME = "(rx:(worker_threads:1))"

#: batches a session's send queue holds per priority (Zenoh: 2, allocated as they are needed).
#: On :data:`NODE_RUNTIME` the task that frees a batch runs on the receiving worker, so a message
#: with blocking congestion control pushed there while every batch of its priority waits to be
#: sent stalls the node until Zenoh closes the link (5 s): a node resumed from SIGSTOP answering
#: the queries queued meanwhile, while its watchdog sent express events (gdb: rx-0 parked in
#: push_network_message under send_response_final; 1 in ~150 hang trials on direct links).
#: Sixteen, Zenoh's most, leaves such a burst room; memory is taken only while it lasts.
TX_QUEUE_BATCHES = 16
PRIORITIES = (
    "control", "real_time", "interactive_high", "interactive_low", "data_high", "data", "data_low", "background"
)  # fmt: skip

#: set beside ``$ZENOH_RUNTIME`` to the runtime tokenring chose (not the user): a node started from
#: such a process gets :data:`NODE_RUNTIME`, where a runtime set since (the user's) is passed on
RUNTIME_CHOSEN = "TOKENRING_ZENOH_RUNTIME_CHOSEN"

#: the token's subscriber runs its callback on the Zenoh thread that received the frame
#: (``indirect=False``): by default zenoh-python hands every sample to a Python thread of its
#: own, a thread switch and a wake per hop. ``TOKENRING_ZENOH_DIRECT=0`` restores the default;
#: bench/RESULTS.md measures both, the bare ring always under the same choice.
DIRECT_CALLBACKS = os.environ.get("TOKENRING_ZENOH_DIRECT", "1") != "0"


def hop_callback(callback: Callable[[zenoh.Sample], object]) -> Any:
    """The handler to subscribe the token path with (see :data:`DIRECT_CALLBACKS`)."""
    if DIRECT_CALLBACKS:
        return zenoh.handlers.Callback(callback, indirect=False)
    return callback


#: how long a client keeps retrying its router before the node reports it cannot connect
CLIENT_CONNECT_TIMEOUT_MS = 60_000

VALID_SCHEMES = ("tcp/", "udp/", "tls/", "quic/", "unixsock-stream/", "ws/")


def check_endpoint(endpoint: str) -> str:
    """Refuse endpoints Zenoh would reject later with a less helpful message."""
    if not endpoint.startswith(VALID_SCHEMES) or ":" not in endpoint.split("/", 1)[1]:
        raise UsageError(
            f"endpoint {endpoint!r} is not of the form tcp/HOST:PORT "
            f"(schemes: {', '.join(s.rstrip('/') for s in VALID_SCHEMES)})"
        )
    return endpoint


_config_in_use: str | None = None  # the Zenoh config file of this process's last session


def unanswered_hint() -> str:
    """What to add to "nobody answered": with a Zenoh config file, the ring may be a secured
    one whose access rules drop this peer's request without a word (tokenring.host.secure)."""
    if _config_in_use is None:
        return ""
    return f"; or does {_config_in_use}'s certificate lack the right on a secured ring"


def make_config(
    *,
    mode: str = "peer",
    connect: Sequence[str] = (),
    listen: Sequence[str] = (),
    config_file: str | None = None,
    block_close_s: float | None = None,
    gossip: bool = True,
) -> zenoh.Config:
    """A Zenoh config; peers listen on an ephemeral loopback port unless told otherwise.
    ``block_close_s``: how long a put with blocking congestion control may wait on a subscriber
    that does not read before Zenoh closes that link, losing what it had not read (Zenoh: 5 s).
    ``gossip`` False: a peer links only to the endpoints it connects to (and those that connect
    to it), retrying them quickly until they listen; gossip would link every peer to every other."""
    path = config_file or os.environ.get("ZENOH_CONFIG")
    global _config_in_use
    _config_in_use = path or None
    try:
        config = zenoh.Config.from_file(path) if path else zenoh.Config()
    except zenoh.ZError as exc:
        raise UsageError(f"cannot read Zenoh config {path}: {exc}") from None
    if mode not in ("peer", "client", "router"):
        raise UsageError(f"Zenoh mode must be peer, client or router, not {mode!r}")
    for endpoint in (*connect, *listen):
        check_endpoint(endpoint)
    config.insert_json5("mode", json.dumps(mode))
    if not path:
        config.insert_json5("scouting/multicast/enabled", "false")
        # Zenoh maps a 16 MB shared-memory pool into a process the first time it sends a message
        # over 3 KB to a peer on this host (a round master's ``rounds`` answer): a third of a
        # node's RSS. The token's frames (514 bytes) never go through it.
        config.insert_json5("transport/shared_memory/transport_optimization/enabled", "false")
        config.insert_json5(
            "transport/link/tx/queue/size", json.dumps(dict.fromkeys(PRIORITIES, TX_QUEUE_BATCHES))
        )
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    elif mode == "peer" and not path:
        config.insert_json5("listen/endpoints", json.dumps(["tcp/127.0.0.1:0"]))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if block_close_s is not None:
        config.insert_json5(
            "transport/link/tx/queue/congestion_control/block/wait_before_close",
            str(int(block_close_s * 1e6)),
        )
    if not gossip:
        config.insert_json5("scouting/gossip/enabled", "false")
        config.insert_json5("connect/timeout_ms", "-1")  # a successor may not listen yet
        config.insert_json5(
            "connect/retry", '{"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}'
        )
    if mode == "client" and not path:
        # Zenoh's clients give up on the first refused connect; a router busy accepting hundreds
        # of nodes (a 255-node ring starting at once) needs them to retry for a while.
        config.insert_json5("connect/timeout_ms", str(CLIENT_CONNECT_TIMEOUT_MS))
        config.insert_json5(
            "connect/retry", '{"period_init_ms": 100, "period_max_ms": 2000, "period_increase_factor": 2}'
        )
    return config


def node_environment(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment for a node (or bare-ring) process: ``base`` (default ``os.environ``)
    with :data:`NODE_RUNTIME`, unless the user set ``$ZENOH_RUNTIME`` there."""
    env = dict(os.environ if base is None else base, PYTHONUNBUFFERED="1")
    _choose_node_runtime(env)
    return env


def use_node_runtime() -> None:
    """Give this process, a node started by hand, :data:`NODE_RUNTIME`, unless the user set
    ``$ZENOH_RUNTIME``; must run before the process's first Zenoh session."""
    _choose_node_runtime(os.environ)


def _choose_node_runtime(env: MutableMapping[str, str]) -> None:
    chosen = env.pop(RUNTIME_CHOSEN, None)
    if env.get("ZENOH_RUNTIME", chosen) == chosen:  # unset, or still the runtime tokenring chose
        env["ZENOH_RUNTIME"] = NODE_RUNTIME


def use_host_runtime() -> None:
    """Give this process :data:`HOST_RUNTIME` (and the nodes it starts :data:`NODE_RUNTIME`),
    unless the user set ``$ZENOH_RUNTIME``; must run before the process's first Zenoh session."""
    if "ZENOH_RUNTIME" not in os.environ:
        os.environ["ZENOH_RUNTIME"] = os.environ[RUNTIME_CHOSEN] = HOST_RUNTIME


#: where Zenoh's error texts say which of its Rust sources raised them (`` at /root/.cargo/...rs:61.``)
_RUST_LOCATION = re.compile(r"\s+at \S+\.rs:\d+\.?")
#: Zenoh's "Can not create a new TCP listener bound to tcp/H:P: [H:P: Address already in use ...]"
_LISTENER_IN_USE = re.compile(r"listener bound to (\S+?):? \[.*Address already in use", re.IGNORECASE)


def zenoh_message(exc: BaseException) -> str:
    """Zenoh's error as one line for a user: its Rust source locations left out, and a listen
    endpoint another process holds said in so many words."""
    text = " ".join(_RUST_LOCATION.sub("", str(exc)).split())
    busy = _LISTENER_IN_USE.search(text)
    if busy:
        return (
            f"cannot listen on {busy.group(1)}: the address is in use by another process "
            "(give another --listen endpoint, or stop that process)"
        )
    return text


def open_session(config: zenoh.Config) -> zenoh.Session:
    """Open a session; Zenoh's own errors become :class:`TransportError` here, once (a malformed
    ``$ZENOH_RUNTIME``, which Zenoh reports by panicking, a :class:`UsageError`)."""
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        message = zenoh_message(exc)
        kind = AddressInUse if _LISTENER_IN_USE.search(" ".join(str(exc).split())) else TransportError
        raise kind(f"cannot open a Zenoh session: {message}") from exc
    except BaseException as exc:  # Zenoh's Rust panics arrive as pyo3's PanicException
        if type(exc).__name__ != "PanicException":
            raise
        if "RuntimeParam" in str(exc) or "SpannedError" in str(exc):  # the user's environment
            raise UsageError(
                f"$ZENOH_RUNTIME={os.environ.get('ZENOH_RUNTIME', '')!r} is not a Zenoh runtime "
                f"configuration (RON, e.g. {NODE_RUNTIME!r}): {exc}"
            ) from None
        raise TransportError(f"Zenoh failed while opening a session: {zenoh_message(exc)}") from None
