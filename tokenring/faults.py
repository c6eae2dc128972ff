"""Fault injection on one node at run time, through its control verb ``fault``.

``tokenring fault <node> <kind> [value]`` reaches a running node on
``tokenring/<ring>/ctl/<ID>/fault`` (msgpack ``{kind, ...options}``) and the node applies it to
itself only; ``all`` sends it to every live node. Kinds:

============  ==============================================================================
crash         the process exits hard at once (exit code 70, as if it had crashed)
hang          the process stops like SIGSTOP (it sends itself SIGSTOP; ``resume`` has the
              launcher send SIGCONT); ``--soft`` freezes only the node OS inside the process
resume        ends a hang
delay MS      every received token waits MS ms (± ``--jitter`` ms) before it is handled
drop P        every received token is discarded with probability P (unacknowledged)
corrupt P     every sent token gets a flipped bit with probability P (the receiver's CRC rejects)
duplicate     every token is sent twice (the receiver recognises the repeat)
lose          the next token is taken (and acknowledged) but never passed on (``--count N``)
leave, join   a clean leave of the ring, and coming back, without ending the process
partition     ``A,B|C,D``: frames and messages no longer cross between the two groups
heal          ends a partition
clear         ends every fault on the node
list          the active faults
============  ==============================================================================

The hooks sit on the token path only while a fault is active; with none they are ``None``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import random
import signal
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from tokenring import keys
from tokenring.control import AfterReply
from tokenring.errors import TokenRingError, UsageError

if TYPE_CHECKING:
    from tokenring.node import NodeOS

log = logging.getLogger("tokenring.faults")

#: faults that may be asked for twice with the effect of once: a lost answer is asked again
IDEMPOTENT = frozenset({"delay", "drop", "corrupt", "duplicate", "partition", "heal", "clear", "list"})

#: a crash or hard hang stops the process this long after its answer was handed to Zenoh: the
#: answer's batch must leave before the process stops (it was 10 ms from *before* the reply,
#: and on a loaded machine the stop won the race: chaos saw "nobody answered" for faults that
#: had taken effect)
AFTER_REPLY_S = 0.05

KINDS = (
    "crash",
    "hang",
    "resume",
    "delay",
    "drop",
    "corrupt",
    "duplicate",
    "lose",
    "leave",
    "join",
    "partition",
    "heal",
    "clear",
    "list",
)
NEEDS_VALUE = {"delay": "MS", "drop": "P", "corrupt": "P", "partition": "A,B|C,D"}


def parse_probability(text: Any, kind: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise UsageError(f"{kind}: probability {text!r} is not a number") from None
    if not 0.0 <= value <= 1.0:
        raise UsageError(f"{kind}: probability {value} is outside 0..1")
    return value


def parse_partition(text: str, resolve: Callable[[str], int]) -> list[list[int]]:
    """``"main,motor|sonar,30"`` → ``[[10, 20], [30, 30]]`` (names or IDs); two disjoint groups."""
    if not isinstance(text, str) or text.count("|") != 1:
        raise UsageError(f"partition {text!r}: expected two groups like 'main,motor|sonar,compass'")
    groups = []
    for part in text.split("|"):
        items = [item.strip() for item in part.split(",") if item.strip()]
        if not items:
            raise UsageError(f"partition {text!r}: a group is empty")
        groups.append(sorted({resolve(item) for item in items}))
    if set(groups[0]) & set(groups[1]):
        raise UsageError(
            f"partition {text!r}: node(s) {sorted(set(groups[0]) & set(groups[1]))} are in both groups"
        )
    return groups


def validate(request: dict[str, Any]) -> dict[str, Any]:
    """Check a fault request before anything is injected; raises :class:`UsageError`."""
    kind = request.get("kind")
    if kind not in KINDS:
        raise UsageError(f"unknown fault kind {kind!r} (kinds: {', '.join(KINDS)})")
    out = {"kind": kind}
    if kind == "delay":
        try:
            out["ms"] = float(request.get("ms", request.get("value")))  # type: ignore[arg-type]  # None: TypeError below
            out["jitter_ms"] = float(request.get("jitter_ms") or 0.0)
        except (TypeError, ValueError):
            raise UsageError("delay needs a number of milliseconds, e.g. 'delay 5'") from None
        if out["ms"] < 0 or out["jitter_ms"] < 0 or out["ms"] > 60_000:
            raise UsageError(f"delay {out['ms']} ms (jitter {out['jitter_ms']}) must be 0..60000 ms")
    elif kind in ("drop", "corrupt"):
        out["p"] = parse_probability(request.get("p", request.get("value")), kind)
    elif kind == "duplicate":
        out["p"] = parse_probability(request.get("p", 1.0), kind)
    elif kind == "lose":
        count = request.get("count") or 1
        if not isinstance(count, int) or count < 1:
            raise UsageError(f"lose --count must be a positive integer, not {count!r}")
        out["count"] = count
    elif kind == "partition":
        groups = request.get("groups")
        if not (
            isinstance(groups, list) and len(groups) == 2 and all(isinstance(g, list) and g for g in groups)
        ):
            raise UsageError("partition needs two groups of node IDs")
        out["groups"] = [[int(i) for i in g] for g in groups]
    elif kind == "hang":
        out["soft"] = bool(request.get("soft", False))
    return out


class FaultInjector:
    """The faults active on one node, and the hooks that apply them on its token path."""

    def __init__(self, os_: NodeOS, exit_process: Callable[[int], None] = os._exit) -> None:
        self.os = os_
        self.active: dict[str, dict[str, Any]] = {}
        self.rng = random.Random()
        self._exit = exit_process
        self._thawed = threading.Event()
        self._thawed.set()
        self._lock = threading.Lock()
        self._pending_stop: threading.Timer | None = None  # a hard hang's SIGSTOP, not sent yet
        self.counts = {"dropped": 0, "corrupted": 0, "duplicated": 0, "lost": 0, "blocked": 0, "delayed": 0}
        self.changed_at = float("-inf")  # time.monotonic() of the last change of the faults
        #: called with the listing after every change (the node process tells the ring, whose
        #: nodes tell a regeneration with a cause from a spurious one: tokenring.regeneration)
        self.on_change: Callable[[dict[str, Any]], None] | None = None

    # -- control ----------------------------------------------------------------------------------
    def handle(self, request: dict[str, Any]) -> dict[str, Any] | AfterReply:
        """Apply one request; returns the active faults afterwards (a crash or a hard hang takes
        effect :data:`AFTER_REPLY_S` after the answer left, so the requester hears it)."""
        spec = validate(request)
        kind = spec["kind"]
        later: threading.Timer | None = None  # started after the ring was told
        with self._lock:
            if kind == "crash":
                from tokenring.launcher import CRASH_EXIT_CODE  # the launcher's, not a node's, module

                later = threading.Timer(AFTER_REPLY_S, self._exit, args=(CRASH_EXIT_CODE,))
            elif kind == "hang":
                if spec["soft"]:
                    self._thawed.clear()
                    self.os.paused = True
                else:
                    later = threading.Timer(AFTER_REPLY_S, os.kill, args=(os.getpid(), signal.SIGSTOP))
                    self._pending_stop = later
                self.active["hang"] = {"since": time.time(), **spec}
            elif kind == "resume":
                self._resume()
            elif kind in ("delay", "drop", "corrupt", "duplicate", "lose", "partition"):
                self.active[kind] = {"since": time.time(), **spec}
            elif kind == "heal":
                self.active.pop("partition", None)
            elif kind == "clear":
                self._resume()
                self.active.clear()
            elif kind == "leave":
                self.os.depart_in_background()
                self.active["leave"] = {"since": time.time(), **spec}
            elif kind == "join":
                self.active.pop("leave", None)
                self.os.join()
            self._install()
            listing = self.listing()
        if kind != "list":
            self._changed(listing)
        if later is not None:
            # started once the answer is sent; the requester learns when the fault takes effect
            return AfterReply({**listing, "effective_in_s": AFTER_REPLY_S}, later.start)
        return listing

    def _changed(self, listing: dict[str, Any]) -> None:
        """The faults changed: note when, and tell whoever listens (never raises)."""
        self.changed_at = time.monotonic()
        if self.on_change is not None:
            try:
                self.on_change(listing)
            except Exception:  # a fault must never take the node down
                log.exception("telling the ring of a fault failed")

    def _resume(self) -> None:
        # a resume within AFTER_REPLY_S of its hang: the SIGSTOP would come after the SIGCONT
        # and stop the node for good (chaos: hang and resume 18 ms apart, node 70 never answered)
        if self._pending_stop is not None:
            self._pending_stop.cancel()
            self._pending_stop = None
        self.active.pop("hang", None)
        self.os.paused = False
        self._thawed.set()

    def listing(self) -> dict[str, Any]:
        return {
            "node": self.os.name,
            "id": self.os.node_id,
            "faults": dict(self.active),
            "counts": dict(self.counts),
        }

    def _install(self) -> None:
        token_path = {"delay", "drop", "corrupt", "duplicate", "lose", "partition"} & set(self.active)
        soft_hang = "hang" in self.active and self.active["hang"].get("soft")
        self.os.rx_fault = self.rx if token_path or soft_hang else None
        self.os.tx_fault = self.tx if token_path or soft_hang else None
        self.os.msg_fault = self.msg if "partition" in self.active or soft_hang else None

    # -- hooks on the token path --------------------------------------------------------------------
    def _other_side(self, node_id: int) -> bool:
        groups = self.active.get("partition", {}).get("groups")
        if not groups:
            return False
        mine = self.os.node_id
        return not any(mine in g and node_id in g for g in groups)

    def rx(self, frame: bytes) -> bool:
        """Before the handler sees a frame; True swallows it."""
        if not self._thawed.is_set():
            self.counts["blocked"] += 1
            self._thawed.wait()
        active = self.active
        if "partition" in active and len(frame) > 1 and self._other_side(frame[0]):
            return True
        delay = active.get("delay")
        if delay:
            jitter = delay["jitter_ms"]
            pause = delay["ms"] + (self.rng.uniform(-jitter, jitter) if jitter else 0.0)
            self.counts["delayed"] += 1
            time.sleep(max(0.0, pause) / 1000.0)
        drop = active.get("drop")
        if drop and self.rng.random() < drop["p"]:
            self.counts["dropped"] += 1
            return True
        return False

    def tx(self, did: int, work: bytearray) -> bool:
        """Before a pass is sent; True means the hook handled (or swallowed) it."""
        if not self._thawed.is_set():
            self._thawed.wait()
        active = self.active
        if "partition" in active and self._other_side(did):
            return True
        lose = active.get("lose")
        if lose:
            lose["count"] -= 1
            if lose["count"] <= 0:
                active.pop("lose", None)
                self._install()
                # the token path must not wait for the notice: it goes from a thread of its own
                threading.Thread(
                    target=self._changed, args=(self.listing(),), name="fault-notice", daemon=True
                ).start()
            self.counts["lost"] += 1
            # the token is gone, not late: an acknowledged pass must not come back as the
            # watchdog's retry (it did on a loaded machine, so no node ever regenerated)
            self.os._ack_pending = False
            return True
        corrupt = active.get("corrupt")
        if corrupt and self.rng.random() < corrupt["p"]:
            bad = bytearray(work)
            bit = self.rng.randrange(self.os.protocol.token_size * 8)
            bad[bit // 8] ^= 1 << (bit % 8)
            self.counts["corrupted"] += 1
            self._send(did, bad)
            return True
        duplicate = active.get("duplicate")
        if duplicate and self.rng.random() < duplicate["p"]:
            self.counts["duplicated"] += 1
            self._send(did, work)  # the normal send follows: the token goes out twice
        return False

    def msg(self, payload: bytes) -> bool:
        """Before a small message (ack, ring event) is handled; True swallows it."""
        if not self._thawed.is_set():
            self._thawed.wait()
        if "partition" in self.active and len(payload) >= 3:
            sender = payload[1] if payload[:1] in (b"A", b"S") else payload[2]
            return sender != 0 and self._other_side(sender)  # 0: the launcher, not a node
        return False

    def _send(self, did: int, frame: bytes | bytearray) -> None:
        with contextlib.suppress(Exception):  # a fault must never take the node down
            self.os.transport.sender(did)(frame)


class FaultClient:
    """The tool side: sends fault requests to nodes of a running ring (``fault``, ``chaos``)."""

    def __init__(self, session: Any, ring: str, timeout: float = 2.0) -> None:
        self.session = session
        self.ring = ring
        self.timeout = timeout

    def inject(self, node_id: int, request: dict[str, Any]) -> dict[str, Any]:
        """Apply a validated request on one node; a real ``resume`` goes through the launcher."""
        from tokenring.cliutil import query_one

        if request["kind"] == "resume" and not request.get("soft"):
            return self.resume(node_id)
        key = keys.control(self.ring, node_id, "fault")
        try:
            return query_one(self.session, key, request, timeout=self.timeout)
        except TokenRingError:
            if request["kind"] not in IDEMPOTENT:
                raise
            # its answer may have been lost on a busy machine: asking twice does no harm
            return query_one(self.session, key, request, timeout=self.timeout)

    def resume(self, node_id: int) -> dict[str, Any]:
        """End a hang: SIGCONT through the launcher (a stopped node answers nothing), then clear."""
        from tokenring.cliutil import query

        deadline = time.monotonic() + self.timeout + 2.0
        refused = ""  # what a launcher said instead of sending it
        while time.monotonic() < deadline:
            # SIGCONT every time round: a hang asked for just before stops its node only after
            # answering (AFTER_REPLY_S), so one SIGCONT can come before the stop it should end
            launcher = query(
                self.session,
                keys.control(self.ring, "launcher", "signal"),
                {"id": node_id, "signal": "CONT"},
                max(0.1, min(self.timeout, deadline - time.monotonic())),
            )
            answer = query(
                self.session, keys.control(self.ring, node_id, "fault"), {"kind": "resume"}, timeout=1.0
            )
            if answer and answer[0][1].get("ok"):
                return answer[0][1]["result"]
            if launcher and not launcher[0][1].get("ok"):
                refused = f" (the launcher: {launcher[0][1].get('error', 'refused')})"
                break
            time.sleep(0.05)  # no answer from either yet: a busy host, ask again until the deadline
        raise UsageError(
            f"node {node_id} does not answer and no launcher of ring {self.ring!r} could send it SIGCONT{refused}; "
            "send SIGCONT to its process yourself (its pid is in 'tokenring status --json')"
        )
