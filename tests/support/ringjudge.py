"""An independent judge of a running ring, written against the wire contract only.

It reads frames as a tap hears them and the probe workload's command ledgers; it imports
nothing from ``tokenring`` (stdlib, PyYAML for protocol.yaml's header offsets and token size,
zenoh for the tap), so a bug in the ring's own wire reader cannot hide a bug in the ring.

**One token** (:func:`one_token`). The node that receives the token from a higher or equal ID
adds 1 to the round counter (byte 4) before passing it on, so with exactly one token every
node's consecutive *fresh* sends carry counters stepping by exactly +1 mod 256. The judge
therefore works per sender, in that sender's own send order (a tap hears each sender over its
own link, so arrival order *across* senders is not send order at full pace, but one sender's
frames arrive in the order it sent them):

* a frame whose length is not token size + 2, whose CRC-16/ARC fails or whose constant
  markers are wrong is no token (a receiver drops it) and is skipped;
* a frame identical, byte for byte, to the same sender's previous frame is a retransmission
  (a retried pass, the ``duplicate`` fault) and is skipped;
* within one epoch (byte 10's low 7 bits plus byte 11, the epoch's origin) the next fresh
  frame of a sender must carry its previous counter + 1. A step of 0 (the same counter with
  different content) or any other step means a second token is going round: a violation;
* a change of epoch (a regeneration or a skip) resets the check for that sender, but a
  sender that goes back to an epoch it had already left is forwarding two tokens: a
  violation.

The rule is strict on purpose: a node that left and rejoined, or was frozen and woke up, may
show a legitimate jump in one epoch, and a tap that misses a frame makes a jump too. Callers
judge a *settled* window, after the faults healed (and poll: a window that still shows the
fault is taken again later); a second token that persists fails every window. A second token
that is a byte-identical copy of the first cannot be told from a retransmission, by the ring
either: content and counters are all the wire has.

With ``members``, the window must also show the token going round through exactly them: every
member sent at least ``k`` fresh frames, each member's last fresh frame went to its successor
among the members (ID order, wrapping), no other node sent a fresh frame, and the members'
last fresh frames all carry one epoch.

**Commands** (:func:`judge_ledgers`). The probe writes one JSON-lines ledger per program
incarnation, ``ledger-<node>-<pid>.jsonl``; every line has ``t`` (``time.time()``)::

    {"ev": "start", "node": N, "run": R, "pid": P}   R names the incarnation
    {"ev": "send", "to": M, "run": R, "n": K}        about to send command K to node M
    {"ev": "outcome", "to": M, "n": K, "result": "acked" | "unacked" | "untransmitted"}
    {"ev": "take", "from": S, "run": R, "n": K}      took command (S, R, K) from the inbox
    {"ev": "quiesced"}                                stopped sending; every send has an outcome
    {"ev": "stop"}                                    ended cleanly (absent: it was killed)

A command is named by (sender node, run, n). The rules:

* **lost**: acknowledged, yet taken by no incarnation of its target;
* **lost_at_receiver_crash**: such a command where the target's incarnation alive at the ack
  (the last one started by then) was killed (no ``stop`` line) and its last ledger line is
  within 1 s after the ack: it reached a program that died before it could log the take. A
  killed incarnation's death is placed at its last line (the probe logs as it goes). Reported
  apart from ``lost``, not a ring loss;
* **duplicated**: taken more than once, counting every incarnation of the receiver;
* **phantom**: taken but never sent (no ``send`` line names it);
* **misdelivered**: taken by a node other than the one it was sent to;
* **pending**: sent without an outcome by an incarnation that was killed (allowed);
  **unresolved**: the same from an incarnation that quiesced or stopped (a violation).

``ok`` = no lost, duplicated, phantom, misdelivered or unresolved command. A taken command
whose outcome was ``unacked`` or ``untransmitted`` is no violation (the token carrying the
ack may have been lost and regenerated from an older copy); they are counted. The judge
relies on the probe writing each line out before it acts on it (a ``send`` line before the
send), so that a killed program leaves no take without its send. A line torn by a kill is
skipped and counted. Judge once every program stopped: until then a running incarnation has
no ``stop`` line and reads as killed (its recent acks as ``lost_at_receiver_crash``).
"""

from __future__ import annotations

import json
import threading
import time
from collections import Counter, defaultdict, deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from tests.support.processes import REPO

PROTOCOL_YAML = REPO / "protocol.yaml"

EPOCH_MASK = 0x7F  # byte 10, bits 0-6: the epoch; bit 7 asks for a pass acknowledgement

CRASH_GRACE_S = 1.0  # an acked command's receiver killed this soon after: lost at the crash


def _crc_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return table


_CRC_TABLE = _crc_table()


def crc16_arc(data: bytes | bytearray) -> int:
    """CRC-16/ARC (reflected 0x8005, init 0): ARCNET's CRC, as the wire contract names it."""
    crc = 0
    table = _CRC_TABLE
    for byte in data:
        crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
    return crc


@dataclass(frozen=True)
class Header:
    """Where the token header's fields sit, and the token's size, as protocol.yaml says."""

    sid: int
    did: int
    counter: int
    epoch: int
    epoch_origin: int
    token_size: int
    consts: tuple[tuple[int, int], ...] = ()  # (offset, value) of the constant markers

    @property
    def frame_size(self) -> int:
        return self.token_size + 2

    @classmethod
    def from_protocol(cls, path: str | Path = PROTOCOL_YAML) -> Header:
        token = yaml.safe_load(Path(path).read_text())["token"]
        fields = token["header"]
        consts = tuple(
            sorted((f["offset"], f["const"]) for f in fields.values() if isinstance(f, dict) and "const" in f)
        )
        return cls(
            sid=fields["sid"]["offset"],
            did=fields["did"]["offset"],
            counter=fields["counter"]["offset"],
            epoch=fields["epoch"]["offset"],
            epoch_origin=fields["epoch_origin"]["offset"],
            token_size=int(token["size"]),
            consts=consts,
        )

    def valid(self, frame: bytes) -> bool:
        """Right length, right CRC (little-endian after the token), right markers."""
        size = self.token_size
        if len(frame) != size + 2:
            return False
        if crc16_arc(frame[:size]) != frame[size] | (frame[size + 1] << 8):
            return False
        return all(frame[offset] == value for offset, value in self.consts)

    def seal(self, token: bytes | bytearray) -> bytes:
        """A frame: the token followed by its CRC (for building test frames)."""
        crc = crc16_arc(token)
        return bytes(token) + bytes((crc & 0xFF, crc >> 8))


class FrameTap:
    """Every frame on ``tokenring/<ring>/token/*`` with its arrival time (``perf_counter``).

    Frames older than ``keep`` seconds are dropped as new ones arrive, so a tap left running
    through a long test module stays bounded (a 10 Mbit/s ring sends ~2000 frames a second)."""

    def __init__(self, session: Any, ring: str, keep: float = 60.0) -> None:
        self.keep = keep
        self._frames: deque[tuple[float, bytes]] = deque()
        self._lock = threading.Lock()
        self._sub = session.declare_subscriber(f"tokenring/{ring}/token/*", self._on)

    def _on(self, sample: Any) -> None:
        now = time.perf_counter()
        frame = sample.payload.to_bytes()
        with self._lock:
            frames = self._frames
            frames.append((now, frame))
            while frames[0][0] < now - self.keep:
                frames.popleft()

    def snapshot(self, since: float | None = None) -> list[tuple[float, bytes]]:
        """The frames heard so far (arrived at or after ``since``, a ``perf_counter`` time)."""
        with self._lock:
            frames = list(self._frames)
        if since is None:
            return frames
        return [f for f in frames if f[0] >= since]

    def close(self) -> None:
        self._sub.undeclare()


@dataclass
class Verdict:
    """What :func:`one_token` found in a window of frames."""

    ok: bool
    problems: list[str]
    frames: int = 0  # every frame in the window
    bad: int = 0  # wrong length, CRC or marker
    repeats: int = 0  # retransmissions
    fresh: dict[int, int] = field(default_factory=dict)  # fresh frames per sender
    epochs: dict[int, list[tuple[int, int]]] = field(default_factory=dict)  # per sender, in order
    last_epoch: dict[int, tuple[int, int]] = field(default_factory=dict)  # per sender
    last_did: dict[int, int] = field(default_factory=dict)  # per sender

    def __str__(self) -> str:
        head = "one token" if self.ok else "NOT one token"
        fresh = ", ".join(f"{s}: {n}" for s, n in sorted(self.fresh.items()))
        text = f"{head}: {self.frames} frames, {self.bad} bad, {self.repeats} repeats, fresh {{{fresh}}}"
        shown = self.problems[:10]
        more = f"\n  ... and {len(self.problems) - 10} more" if len(self.problems) > 10 else ""
        return text + "".join(f"\n  {p}" for p in shown) + more


def one_token(
    frames: Iterable[tuple[float, bytes]],
    header: Header,
    members: Iterable[int] | None = None,
    k: int = 3,
) -> Verdict:
    """Judge a window of ``(arrival time, frame)`` captures: exactly one token (and, with
    ``members``, going round through exactly them). The rules are in the module docstring."""
    problems: list[str] = []
    by_sender: dict[int, list[bytes]] = defaultdict(list)
    total = bad = 0
    for _, frame in frames:  # arrival order: each sender's own send order
        total += 1
        frame = bytes(frame)
        if not header.valid(frame):
            bad += 1
            continue
        by_sender[frame[header.sid]].append(frame)

    repeats = 0
    fresh: dict[int, int] = {}
    epochs: dict[int, list[tuple[int, int]]] = {}
    last_epoch: dict[int, tuple[int, int]] = {}
    last_did: dict[int, int] = {}
    for sid, sent in sorted(by_sender.items()):
        previous: bytes | None = None
        count = 0
        seen: list[tuple[int, int]] = []
        for index, frame in enumerate(sent):
            if frame == previous:
                repeats += 1
                continue
            epoch = (frame[header.epoch] & EPOCH_MASK, frame[header.epoch_origin])
            counter = frame[header.counter]
            if previous is not None:
                before = (previous[header.epoch] & EPOCH_MASK, previous[header.epoch_origin])
                if epoch == before:
                    step = (counter - previous[header.counter]) & 0xFF
                    if step == 0:
                        problems.append(
                            f"sender {sid} frame {index}: counter {counter} sent again with other "
                            f"content in epoch {epoch} (a second token)"
                        )
                    elif step != 1:
                        problems.append(
                            f"sender {sid} frame {index}: counter {previous[header.counter]} -> "
                            f"{counter} in epoch {epoch} (a jump: a second token)"
                        )
                elif epoch in seen:
                    problems.append(
                        f"sender {sid} frame {index}: back to epoch {epoch} after {before} "
                        f"(counter {counter}: two tokens through one node)"
                    )
            if not seen or seen[-1] != epoch:
                seen.append(epoch)
            previous = frame
            count += 1
        fresh[sid] = count
        epochs[sid] = seen
        last_epoch[sid] = seen[-1]
        last_did[sid] = previous[header.did] if previous is not None else -1

    if members is not None:
        problems.extend(_membership_problems(sorted(set(members)), fresh, last_epoch, last_did, k))

    return Verdict(
        ok=not problems,
        problems=problems,
        frames=total,
        bad=bad,
        repeats=repeats,
        fresh=fresh,
        epochs=epochs,
        last_epoch=last_epoch,
        last_did=last_did,
    )


def _membership_problems(
    ring: Sequence[int],
    fresh: dict[int, int],
    last_epoch: dict[int, tuple[int, int]],
    last_did: dict[int, int],
    k: int,
) -> list[str]:
    """Why the window does not show one token going round through exactly ``ring``."""
    problems = []
    if not ring:
        return ["no members given"]
    successor = {a: b for a, b in zip(ring, [*ring[1:], ring[0]], strict=True)}
    for member in ring:
        sent = fresh.get(member, 0)
        if sent < k:
            problems.append(f"member {member} sent {sent} fresh frames (fewer than {k})")
        elif last_did[member] != successor[member]:
            problems.append(
                f"member {member} last passed to {last_did[member]}, not to its successor {successor[member]}"
            )
    for sid, sent in sorted(fresh.items()):
        if sid not in successor and sent:
            problems.append(f"sender {sid} is no member but sent {sent} fresh frames")
    final = {last_epoch[m] for m in ring if m in last_epoch}
    if len(final) > 1:
        problems.append(f"the members end in {len(final)} epochs: {sorted(final)}")
    return problems


# ---------------------------------------------------------------------------------------------
# the command ledgers


@dataclass
class Incarnation:
    """One run of the probe program on one node, as its ledger tells it."""

    node: int
    run: int
    pid: int
    path: Path
    started: float
    last: float  # the time of its last line
    quiesced: float | None = None
    stopped: float | None = None

    @property
    def killed(self) -> bool:
        return self.stopped is None


CommandId = tuple[int, int, int]  # (sender node, run, n)


@dataclass
class CommandVerdict:
    """What :func:`judge_ledgers` found; every list holds command ids ``(sender, run, n)``."""

    ok: bool
    incarnations: list[Incarnation]
    sent: int = 0
    acked: int = 0
    unacked: int = 0
    untransmitted: int = 0
    taken: int = 0  # take lines
    taken_unacked: int = 0  # taken although the sender heard "unacked" or "untransmitted"
    torn: int = 0  # unreadable lines (a kill mid-write)
    lost: list[CommandId] = field(default_factory=list)
    lost_at_receiver_crash: list[CommandId] = field(default_factory=list)
    duplicated: list[CommandId] = field(default_factory=list)
    phantom: list[CommandId] = field(default_factory=list)
    misdelivered: list[CommandId] = field(default_factory=list)
    pending: list[CommandId] = field(default_factory=list)
    unresolved: list[CommandId] = field(default_factory=list)
    acked_at: dict[CommandId, float] = field(default_factory=dict)  # the acked outcome's t

    def __str__(self) -> str:
        head = "commands ok" if self.ok else "commands NOT ok"
        text = (
            f"{head}: {len(self.incarnations)} incarnations, sent {self.sent}, acked {self.acked}, "
            f"unacked {self.unacked}, untransmitted {self.untransmitted}, taken {self.taken}, "
            f"pending {len(self.pending)}, lost at a receiver crash {len(self.lost_at_receiver_crash)}"
        )
        for name in ("lost", "duplicated", "phantom", "misdelivered", "unresolved"):
            ids = getattr(self, name)
            if ids:
                text += f"\n  {name} ({len(ids)}): {ids[:10]}"
        return text


def _parse(raw: str) -> dict | None:
    """One ledger line, or None if it is not a JSON object with a time and an event."""
    try:
        line = json.loads(raw)
        float(line["t"])
        str(line["ev"])
    except (ValueError, KeyError, TypeError):
        return None
    return line if isinstance(line, dict) else None


def _read_ledger(path: Path) -> tuple[list[tuple[Incarnation, list[dict]]], int]:
    """The incarnations in one ledger file with their lines (a reused PID's file may hold
    several, each from its ``start`` line), and how many lines were unreadable."""
    out: list[tuple[Incarnation, list[dict]]] = []
    torn = 0
    for raw in path.read_text(errors="replace").splitlines():
        if not raw.strip():
            continue
        line = _parse(raw)
        if line is None:
            # a line torn by a kill; the next incarnation of a reused PID appends its first
            # line to the fragment: that line is read from the fragment's last "{"
            torn += 1
            starts = [i for i, c in enumerate(raw) if c == "{" and i]
            line = next((p for p in map(_parse, (raw[i:] for i in reversed(starts))) if p), None)
            if line is None:
                continue
        t, ev = float(line["t"]), line["ev"]
        if ev == "start":
            try:
                inc = Incarnation(int(line["node"]), int(line["run"]), int(line["pid"]), path, t, t)
            except (ValueError, KeyError, TypeError):
                torn += 1
                continue
            out.append((inc, []))
            continue
        if not out:
            torn += 1  # a line before any start: no incarnation to give it to
            continue
        inc, lines = out[-1]
        inc.last = max(inc.last, t)
        if ev == "quiesced":
            inc.quiesced = t
        elif ev == "stop":
            inc.stopped = t
        else:
            lines.append(line)
    return out, torn


def judge_ledgers(directory: str | Path) -> CommandVerdict:
    """Judge every ``ledger-*.jsonl`` in ``directory`` (rules in the module docstring)."""
    incarnations: list[Incarnation] = []
    sends: dict[CommandId, tuple[int, Incarnation]] = {}  # id -> (target, sender incarnation)
    outcomes: dict[CommandId, tuple[str, float]] = {}
    takes: dict[CommandId, list[tuple[int, float]]] = defaultdict(list)  # id -> [(taker, t)]
    torn = 0
    results: Counter[str] = Counter()
    for path in sorted(Path(directory).glob("ledger-*.jsonl")):
        parsed, bad = _read_ledger(path)
        torn += bad
        for inc, lines in parsed:
            incarnations.append(inc)
            mine: dict[int, CommandId] = {}  # n -> the id its send line gave it
            for line in lines:
                try:
                    ev = line["ev"]
                    if ev == "send":
                        n = int(line["n"])
                        mine[n] = (inc.node, int(line["run"]), n)
                        sends[mine[n]] = (int(line["to"]), inc)
                    elif ev == "outcome":
                        n = int(line["n"])
                        result = str(line["result"])
                        outcomes[mine.get(n, (inc.node, inc.run, n))] = (result, float(line["t"]))
                        results[result] += 1
                    elif ev == "take":
                        key = (int(line["from"]), int(line["run"]), int(line["n"]))
                        takes[key].append((inc.node, float(line["t"])))
                except (ValueError, KeyError, TypeError):
                    torn += 1

    by_node: dict[int, list[Incarnation]] = defaultdict(list)
    for inc in incarnations:
        by_node[inc.node].append(inc)
    for runs in by_node.values():
        runs.sort(key=lambda i: i.started)

    verdict = CommandVerdict(
        ok=False,
        incarnations=incarnations,
        sent=len(sends),
        acked=results["acked"],
        unacked=results["unacked"],
        untransmitted=results["untransmitted"],
        taken=sum(len(v) for v in takes.values()),
        torn=torn,
    )
    for cid, (target, sender) in sorted(sends.items()):
        outcome = outcomes.get(cid)
        taken_by = [node for node, _ in takes.get(cid, ())]
        if outcome is not None and outcome[0] == "acked":
            verdict.acked_at[cid] = outcome[1]
        if outcome is None:
            (verdict.pending if sender.killed and sender.quiesced is None else verdict.unresolved).append(cid)
        elif outcome[0] == "acked" and target not in taken_by:
            alive = _alive_at(by_node.get(target, []), outcome[1])
            if alive is not None and alive.killed and alive.last <= outcome[1] + CRASH_GRACE_S:
                verdict.lost_at_receiver_crash.append(cid)
            else:
                verdict.lost.append(cid)
        elif outcome[0] != "acked" and taken_by:
            verdict.taken_unacked += 1
        if any(node != target for node in taken_by):
            verdict.misdelivered.append(cid)
    for cid, taken in sorted(takes.items()):
        if cid not in sends:
            verdict.phantom.append(cid)
        if len(taken) > 1:
            verdict.duplicated.append(cid)
    verdict.ok = not (
        verdict.lost or verdict.duplicated or verdict.phantom or verdict.misdelivered or verdict.unresolved
    )
    return verdict


def _alive_at(runs: list[Incarnation], t: float) -> Incarnation | None:
    """The incarnation of a node alive at ``t``: the last one started by then, unless it
    had stopped cleanly before ``t``."""
    alive = None
    for inc in runs:
        if inc.started <= t:
            alive = inc
    if alive is not None and alive.stopped is not None and alive.stopped < t:
        return None
    return alive
