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

This is the vocabulary both sides share: the kinds, their checks, the crash's exit code.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from tokenring.errors import UsageError

#: exit code of a node process killed on purpose by the ``crash`` fault
CRASH_EXIT_CODE = 70

#: faults that may be asked for twice with the effect of once: a lost answer is asked again
IDEMPOTENT = frozenset({"delay", "drop", "corrupt", "duplicate", "partition", "heal", "clear", "list"})


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
