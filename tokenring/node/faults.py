"""The faults active on one node and the hooks that apply them on its token path
(the kinds: :mod:`tokenring.contract.faults`)."""

from __future__ import annotations

import contextlib
import logging
import os
import signal
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from tokenring import runtime
from tokenring.contract.faults import validate
from tokenring.transport.control import AfterReply

if TYPE_CHECKING:
    from tokenring.node.node_os import NodeOS


log = logging.getLogger("tokenring.faults")


#: a crash or hard hang stops the process this long after its answer was handed to Zenoh: the
#: answer's batch must leave before the process stops (timed from before the reply, a loaded
#: machine's stop won the race and chaos heard nobody answer a fault that had taken effect)
AFTER_REPLY_S = 0.05


class FaultInjector:
    """The faults active on one node, and the hooks that apply them on its token path."""

    def __init__(self, os_: NodeOS, exit_process: Callable[[int], None] = os._exit) -> None:
        self._rt = rt = runtime.current()
        self.os = os_
        self.active: dict[str, dict[str, Any]] = {}
        self.rng = rt.rng()
        self._exit = exit_process
        self._thawed = rt.event()
        self._thawed.set()
        self._lock = rt.lock()
        self._pending_stop: Any = None  # a hard hang's SIGSTOP (a timer), not sent yet
        self.counts = {"dropped": 0, "corrupted": 0, "duplicated": 0, "lost": 0, "blocked": 0, "delayed": 0}
        self.changed_at = float("-inf")  # the runtime's monotonic clock at the last change of the faults
        #: called with the listing after every change (the node process tells the ring, whose
        #: nodes tell a regeneration with a cause from a spurious one: tokenring.node.regeneration)
        self.on_change: Callable[[dict[str, Any]], None] | None = None

    # -- control ----------------------------------------------------------------------------------
    def handle(self, request: dict[str, Any]) -> dict[str, Any] | AfterReply:
        """Apply one request; returns the active faults afterwards (a crash or a hard hang takes
        effect :data:`AFTER_REPLY_S` after the answer left, so the requester hears it)."""
        spec = validate(request)
        kind = spec["kind"]
        later: Any = None  # a timer, started after the ring was told
        rt = self._rt
        with self._lock:
            if kind == "crash":
                from tokenring.contract.faults import CRASH_EXIT_CODE  # the launcher's, not a node's, module

                later = rt.timer(AFTER_REPLY_S, self._exit, (CRASH_EXIT_CODE,))
            elif kind == "hang":
                if spec["soft"]:
                    self._thawed.clear()
                    self.os.paused = True
                else:
                    later = rt.timer(AFTER_REPLY_S, os.kill, (os.getpid(), signal.SIGSTOP))
                    self._pending_stop = later
                self.active["hang"] = {"since": rt.time(), **spec}
            elif kind == "resume":
                self._resume()
            elif kind in ("delay", "drop", "corrupt", "duplicate", "lose", "partition"):
                self.active[kind] = {"since": rt.time(), **spec}
            elif kind == "heal":
                self.active.pop("partition", None)
            elif kind == "clear":
                self._resume()
                self.active.clear()
            elif kind == "leave":
                self.os.depart_in_background()
                self.active["leave"] = {"since": rt.time(), **spec}
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
        self.changed_at = self._rt.monotonic()
        if self.on_change is not None:
            try:
                self.on_change(listing)
            except Exception:  # a fault must never take the node down
                log.exception("telling the ring of a fault failed")

    def _resume(self) -> None:
        # a resume within AFTER_REPLY_S of its hang: the SIGSTOP would come after the SIGCONT
        # and stop the node for good
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
            self._rt.sleep(max(0.0, pause) / 1000.0)
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
                listing = self.listing()
                self._rt.spawn(lambda: self._changed(listing), "fault-notice")
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
