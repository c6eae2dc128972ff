"""tokenring's own share per hop with both rings in the same seconds: interleaved windows.

Separate runs of the ring and of the bare Zenoh ring land in different seconds of the host, and
a virtual machine's host takes CPUs for seconds at a time (steal time): even pairs of runs
screened by their steal spread too widely to tell a few microseconds per hop. So here both
rings are up at once and take turns: the
one not measured is frozen (SIGSTOP to each of its processes, SIGCONT to resume). The windows
go bare, ring, bare, ..., bare, and each ring window is paired with the bare windows on either
side of it, so a steady drift of the host's speed cancels. A pair's own share is
``(ring window's median - mean of the two bare windows' medians) / N``; over many pairs, their mean with its
95 % interval (:func:`tokenring.perf.hop_overhead.interval`), beside the same over the pairs whose two
windows lost at most :data:`~tokenring.perf.hop_overhead.STEAL_LIMIT_PCT` to the host.

A window is short enough that a frozen ring hardly notices: a node whose watchdog wakes more
than :data:`tokenring.node.recovery.FROZEN_AFTER_S` late announces a rejoin (255 of them at once
would be a storm no ring sees in use). A watchdog due just before a resume does not see its
process was frozen and can regenerate the token (now and then in a hundred pairs); the record
counts the nodes' warnings and keeps the first few. The round that spans a
freeze and the next ``settle`` rounds are dropped; the ring's rounds are its round master's (the time between two of
its visits, as ``tokenring bench`` reports them), the bare ring's are its process 0's.

    tokenring bench --interleave 100 --nodes 64 --topology router
    tokenring bench --interleave 150 --nodes 255 --topology links --json F
"""

from __future__ import annotations

import contextlib
import itertools
import os
import signal
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from tokenring.perf.hop_overhead import (
    STEAL_LIMIT_PCT,
    cpu_jiffies,
    interval,
    pair_share_us,
    steal_pct,
    within_steal_limit,
)
from tokenring.perf.running_rings import BareRing, LiveRing

#: a window's share of the freeze a node can sleep through unnoticed (FROZEN_AFTER_S)
WINDOW_OF_FROZEN = 0.6
#: rounds dropped after a resume: the frozen ring's first rounds carry what queued meanwhile
SETTLE_ROUNDS = 2
TOPOLOGIES = ("peer", "router", "links")


def signal_all(pids: list[int], signum: int) -> None:
    """Send ``signum`` to each of ``pids`` (one that has already gone is skipped)."""
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signum)


def window_rounds(stamps: list[float], start: float, end: float, settle: int) -> list[float]:
    """The bare ring's rounds (s) in one window: between arrival ``stamps`` (sorted, monotonic
    clock) from ``start`` (the resume) to ``end`` (the freeze), without the first ``settle``."""
    inside = [t for t in stamps if start <= t <= end]
    return [b - a for a, b in itertools.pairwise(inside)][settle:]


def since_resume(rounds: list[float], running_s: float, settle: int) -> list[float]:
    """The ring's rounds (s) since its resume: the longest tail of ``rounds`` (oldest first) that
    fits in the ``running_s`` the ring ran before they were asked for, without its first
    ``settle``. The round that spans the freeze began before it and does not fit; a round that
    was only slow does, so no slow round is mistaken for the freeze."""
    total, first = 0.0, len(rounds)
    while first > 0 and total + rounds[first - 1] <= running_s:
        first -= 1
        total += rounds[first]
    return rounds[first + settle :]


def window_share_us(ring: list[float], before: list[float], after: list[float], nodes: int) -> float:
    """One pair's own share per hop (µs): the ring window's median round (s) against the mean of
    the medians of the bare windows before and after it (a steady drift of the host cancels)."""
    bare_s = (statistics.median(before) + statistics.median(after)) / 2
    return pair_share_us(statistics.median(ring) * 1e3, bare_s * 1e3, nodes)


def default_window_s() -> float:
    """A window's length unless told: :data:`WINDOW_OF_FROZEN` of the freeze a node sleeps through."""
    from tokenring.node.recovery import FROZEN_AFTER_S

    return WINDOW_OF_FROZEN * FROZEN_AFTER_S


def interleave(
    nodes: int,
    topology: str,
    pairs: int,
    window_s: float | None = None,
    settle: int = SETTLE_ROUNDS,
    say: Callable[[str], None] = lambda _text: None,
    bitrate: str = "max",
    ack_mode: str = "adaptive",
) -> dict[str, Any]:
    """Run the two rings of ``nodes`` in ``topology`` side by side for ``pairs`` pairs of windows
    (each ``window_s``, default :func:`default_window_s`); the own share per hop over all pairs
    and over the calm ones, each pair's medians and steal. ``bitrate`` and ``ack_mode`` are the
    ring's (the bare ring has neither)."""
    window_s = window_s or default_window_s()
    router, links = topology in ("router", "links"), topology == "links"
    t_begin = time.monotonic()
    say(f"bare Zenoh ring of {nodes} ({topology}) forming")
    bare = BareRing(nodes, router, chain=links)
    ring: LiveRing | None = None
    try:
        bare.wait_circulating(60 + nodes)
        # the bare ring runs on while the ring forms: frozen for a minute, its clients' Zenoh
        # leases would end
        say(f"tokenring ring of {nodes} ({topology}) forming")
        ring = LiveRing(nodes, router, links, bitrate=bitrate, ack_mode=ack_mode)
        ring.wait_circulating(60 + 1.5 * nodes)
        ring_pids = ring.pids
        signal_all(bare.pids + ring_pids, signal.SIGSTOP)
        say(f"both rings up ({time.monotonic() - t_begin:.0f} s): {pairs} pairs of {window_s:.2f} s windows")
        warnings_before = len(ring.output.getvalue().splitlines())
        bare_windows: list[tuple[float, float]] = []
        ring_rounds: list[list[float]] = []
        window_steal: list[float] = []  # % of the CPUs the host took, window by window
        for index in range(2 * pairs + 1):  # bare, ring, bare, ..., ring, bare
            measuring_ring = index % 2 == 1
            pids = ring_pids if measuring_ring else bare.pids
            jiffies = cpu_jiffies()
            signal_all(pids, signal.SIGCONT)
            start = time.monotonic()
            time.sleep(window_s)
            rounds = (ring.answer("rounds") or []) if measuring_ring else []
            end = time.monotonic()
            signal_all(pids, signal.SIGSTOP)
            window_steal.append(steal_pct(jiffies, cpu_jiffies()))
            if measuring_ring:
                ring_rounds.append(since_resume(rounds, end - start, settle))
            else:
                bare_windows.append((start, end))
                done = index // 2
                if done and done % max(1, pairs // 10) == 0:
                    say(f"pair {done}/{pairs} ({time.monotonic() - t_begin:.0f} s)")
        warned = ring.output.getvalue().splitlines()[warnings_before:]
    finally:
        # whatever was frozen when this ended (an error, Ctrl-C): a frozen process cannot stop
        signal_all(bare.pids + (ring.pids if ring is not None else []), signal.SIGCONT)
        stamps = bare.stop()
        if ring is not None:
            ring.stop()
    bare_rounds = [window_rounds(stamps, start, end, settle) for start, end in bare_windows]
    record = summarize(nodes, topology, window_s, settle, ring_rounds, bare_rounds, window_steal, len(warned))
    record["ring_warning_lines"] = [line[:200] for line in warned[:5]]  # what the nodes said, if anything
    record["pids"] = {"ring": ring_pids, "bare": bare.pids}
    record["bitrate"], record["ack"] = bitrate, ack_mode
    return record


def p99_ms(rounds: list[float]) -> float | None:
    """The 99th percentile (ms, linear between ranks) of round times in s; None for none."""
    if not rounds:
        return None
    return float(np.percentile(rounds, 99)) * 1e3


def summarize(
    nodes: int,
    topology: str,
    window_s: float,
    settle: int,
    ring_rounds: list[list[float]],
    bare_rounds: list[list[float]],
    window_steal: list[float],
    warnings: int,
) -> dict[str, Any]:
    """The record of an interleaved run from its ring windows' rounds (s), the bare windows'
    around them (one more) and every window's steal (%, in time order: bare, ring, ..., bare):
    each pair's medians and steal, the own share per hop over the pairs with rounds in all three
    windows and over the calm ones among them."""
    pairs = len(ring_rounds)
    if len(bare_rounds) != pairs + 1 or len(window_steal) != 2 * pairs + 1:
        raise ValueError("an interleaved run has a bare window before and after each ring window")
    usable = [i for i in range(pairs) if ring_rounds[i] and bare_rounds[i] and bare_rounds[i + 1]]
    # (ring, bare) steal of each pair: a bare figure is the worse of its two windows'
    steal = [
        (round(window_steal[2 * i + 1], 1), round(max(window_steal[2 * i], window_steal[2 * i + 2]), 1))
        for i in range(pairs)
    ]
    shares = {i: window_share_us(ring_rounds[i], bare_rounds[i], bare_rounds[i + 1], nodes) for i in usable}
    calm_pairs = [i for i in usable if within_steal_limit(steal[i])]
    calm = [shares[i] for i in calm_pairs]
    pooled_ring = [x for i in usable for x in ring_rounds[i]]
    pooled_bare = [x for rounds in bare_rounds for x in rounds]
    calm_ring = [x for i in calm_pairs for x in ring_rounds[i]]
    # a bare window is calm when it lost at most the limit itself (window 2k of the time line)
    calm_bare = [
        x for k, rounds in enumerate(bare_rounds) if window_steal[2 * k] <= STEAL_LIMIT_PCT for x in rounds
    ]
    return {
        "nodes": nodes,
        "topology": topology,
        "window_s": window_s,
        "settle_rounds": settle,
        "pairs": pairs,
        "pairs_usable": len(usable),
        "steal_limit_pct": STEAL_LIMIT_PCT,
        "pair_steal_pct": steal,
        "pair_shares_us": [round(shares[i], 2) if i in shares else None for i in range(pairs)],
        "ring_medians_ms": [round(statistics.median(r) * 1e3, 4) if r else None for r in ring_rounds],
        "bare_medians_ms": [round(statistics.median(b) * 1e3, 4) if b else None for b in bare_rounds],
        "ring_rounds": [len(r) for r in ring_rounds],
        "ring_measured_s": [round(sum(r), 4) for r in ring_rounds],  # of each window's length
        "bare_rounds": [len(b) for b in bare_rounds],
        "own_share_us": interval(calm),
        "own_share_all_us": interval(list(shares.values())),
        "pooled_median_ms": {
            "ring": statistics.median(pooled_ring) * 1e3 if pooled_ring else None,
            "bare": statistics.median(pooled_bare) * 1e3 if pooled_bare else None,
        },
        "ring_warnings": warnings,
        # the tail over every round of the windows, and over the windows within the steal limit:
        # a run's mean steal hides the host's sub-second bursts, a window's does not
        "pooled_p99_ms": {"ring": p99_ms(pooled_ring), "bare": p99_ms(pooled_bare)},
        "calm_p99_ms": {"ring": p99_ms(calm_ring), "bare": p99_ms(calm_bare)},
    }
