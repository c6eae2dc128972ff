"""The chaos checker for commands: reads the probe's ledgers after the ring stopped.

``tokenring chaos`` runs :mod:`tokenring.chaos.probe` on every node with
``$TOKENRING_PROBE_LEDGER`` set; each program incarnation appends what it sent, what came of it
and what it took (see that module). Judged here, apart from the system under test (like a
Jepsen checker), once every process has stopped:

- **lost**: acknowledged, yet taken by no incarnation of the target;
- **duplicated**: taken more than once (across the target's incarnations);
- **phantom**: taken, never sent;
- **lost at a receiver crash**: acknowledged and not taken where the target's incarnation that
  was alive at the acknowledgement was killed within a second after it — the command reached a
  program that died before it could write it down; counted apart, not as a ring loss.

A command is ``(sender node, run, n)``; ``run`` is the sender incarnation's random tag.
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CRASH_WINDOW_S = 1.0

CommandId = tuple[int, int, int]


@dataclass
class Incarnation:
    """One probe program's life on one node, read from its ledger file."""

    node: int
    run: int
    started: float
    last: float
    stopped: bool
    quiesced: bool


@dataclass
class Verdict:
    """What the ledgers say about every command of a chaos run."""

    sent: int = 0
    acked: int = 0
    unacked: int = 0
    untransmitted: int = 0
    taken: int = 0
    lost: list[CommandId] = field(default_factory=list)
    duplicated: list[CommandId] = field(default_factory=list)
    phantom: list[CommandId] = field(default_factory=list)
    lost_at_receiver_crash: list[CommandId] = field(default_factory=list)
    incarnations: int = 0
    unreadable_lines: int = 0
    acked_at: dict[CommandId, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not (self.lost or self.duplicated or self.phantom)

    def lost_between(self, start: float, end: float) -> int:
        """Lost commands whose acknowledgement came in ``[start, end)`` (wall-clock seconds)."""
        return sum(1 for c in self.lost if start <= self.acked_at.get(c, -1.0) < end)

    def as_dict(self) -> dict[str, Any]:
        return {
            "sent": self.sent,
            "acked": self.acked,
            "unacked": self.unacked,
            "untransmitted": self.untransmitted,
            "taken": self.taken,
            "lost": len(self.lost),
            "duplicated": len(self.duplicated),
            "phantom": len(self.phantom),
            "lost_at_receiver_crash": len(self.lost_at_receiver_crash),
            "incarnations": self.incarnations,
            "examples": {
                "lost": [list(c) for c in self.lost[:5]],
                "duplicated": [list(c) for c in self.duplicated[:5]],
                "phantom": [list(c) for c in self.phantom[:5]],
            },
        }


def _read(path: Path) -> tuple[list[dict[str, Any]], int]:
    entries, bad = [], 0
    for line in path.read_text(errors="replace").splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            bad += 1  # a line cut short by a kill
            continue
        if isinstance(entry, dict) and "ev" in entry:
            entries.append(entry)
        else:
            bad += 1
    return entries, bad


def judge(directory: str | Path) -> Verdict:
    """Judge every ledger file in ``directory``."""
    verdict = Verdict()
    sends: dict[CommandId, int] = {}  # -> target
    outcomes: dict[CommandId, tuple[str, float]] = {}
    takes: Counter[CommandId] = Counter()
    lives: dict[int, list[Incarnation]] = {}
    for path in sorted(Path(directory).glob("ledger-*.jsonl")):
        entries, bad = _read(path)
        verdict.unreadable_lines += bad
        if not entries or entries[0].get("ev") != "start":
            continue
        head = entries[0]
        node, run = int(head["node"]), int(head["run"])
        life = Incarnation(node, run, head["t"], entries[-1]["t"], False, False)
        lives.setdefault(node, []).append(life)
        for e in entries[1:]:
            ev = e["ev"]
            if ev == "send":
                sends[(node, run, int(e["n"]))] = int(e["to"])
            elif ev == "outcome":
                outcomes[(node, run, int(e["n"]))] = (str(e["result"]), float(e["t"]))
            elif ev == "take":
                takes[(int(e["from"]), int(e["run"]), int(e["n"]))] += 1
            elif ev == "stop":
                life.stopped = True
            elif ev == "quiesced":
                life.quiesced = True
    verdict.incarnations = sum(len(v) for v in lives.values())
    verdict.sent = len(sends)
    verdict.taken = sum(takes.values())
    for command, (result, at) in outcomes.items():
        if result == "acked":
            verdict.acked += 1
            verdict.acked_at[command] = at
        elif result == "unacked":
            verdict.unacked += 1
        else:
            verdict.untransmitted += 1
    for command, at in verdict.acked_at.items():
        if takes[command]:
            continue
        target = sends.get(command)
        # the target's incarnation alive at the acknowledgement: the latest one started before it
        started = [life for life in lives.get(target or -1, []) if life.started <= at]
        receiver = max(started, key=lambda life: life.started, default=None)
        if receiver is not None and not receiver.stopped and receiver.last - at <= CRASH_WINDOW_S:
            verdict.lost_at_receiver_crash.append(command)
        else:
            verdict.lost.append(command)
    verdict.duplicated = sorted(c for c, count in takes.items() if count > 1)
    verdict.phantom = sorted(c for c in takes if c not in sends)
    verdict.lost.sort()
    return verdict
