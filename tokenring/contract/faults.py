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

import math
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

#: the longest delay (and jitter) a node's token may be held, in ms: longer is a hang
MAX_DELAY_MS = 60_000
#: the most tokens one ``lose`` takes (each costs the ring a regeneration)
MAX_LOSE = 10_000


def number_within(value: Any, what: str, low: float, high: float, unit: str = "") -> float:
    """``value`` as a finite float within ``low``..``high``, else a :class:`UsageError` naming
    ``what`` and the range: NaN, infinities, booleans and numbers too large for a float are
    refused here, on the tool's side and on the node's alike (a node must never die of one)."""
    span = f"{low:g}..{high:g}{f' {unit}' if unit else ''}"
    try:
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise TypeError
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise UsageError(f"{what} {value!r} is not a number (give {span})") from None
    if not (math.isfinite(number) and low <= number <= high):
        raise UsageError(f"{what} {value!r} is outside {span}")
    return number


def parse_probability(text: Any, kind: str) -> float:
    return number_within(text, f"{kind}: probability", 0.0, 1.0)


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
    if not isinstance(request, dict):
        raise UsageError(
            f"a fault request is a mapping like {{'kind': 'delay', 'ms': 5}}, not {type(request).__name__}"
        )
    kind = request.get("kind")
    if kind not in KINDS:
        raise UsageError(f"unknown fault kind {kind!r} (kinds: {', '.join(KINDS)})")
    out = {"kind": kind}
    if kind == "delay":
        ms = request.get("ms", request.get("value"))
        if ms is None:
            raise UsageError("delay needs a number of milliseconds, e.g. 'delay 5'")
        out["ms"] = number_within(ms, "delay", 0, MAX_DELAY_MS, "ms")
        out["jitter_ms"] = number_within(request.get("jitter_ms") or 0.0, "--jitter", 0, MAX_DELAY_MS, "ms")
    elif kind in ("drop", "corrupt"):
        out["p"] = parse_probability(request.get("p", request.get("value")), kind)
    elif kind == "duplicate":
        out["p"] = parse_probability(request.get("p", 1.0), kind)
    elif kind == "lose":
        count = 1 if request.get("count") is None else request["count"]
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_LOSE:
            raise UsageError(f"lose --count {count!r}: give a whole number within 1..{MAX_LOSE}")
        out["count"] = count
    elif kind == "partition":
        groups = request.get("groups")
        if not (
            isinstance(groups, list)
            and len(groups) == 2
            and all(isinstance(g, list) and 0 < len(g) <= 255 for g in groups)
            and all(
                isinstance(i, int) and not isinstance(i, bool) and 1 <= i <= 255 for g in groups for i in g
            )
        ):
            raise UsageError("partition needs two groups of node IDs (each 1..255)")
        out["groups"] = [list(g) for g in groups]
    elif kind == "hang":
        out["soft"] = bool(request.get("soft", False))
    return out
