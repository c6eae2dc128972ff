"""The suite's own share per hop: issue 23's aim, the retake rule, the pairs per size.

The figures themselves (a pair's share, the 95 % interval, the host's steal time) are
:mod:`tokenring.perf.hop_overhead`'s, shared with ``tokenring bench``. Here: a pair in which either run
lost more than :data:`~tokenring.perf.hop_overhead.STEAL_LIMIT_PCT` of the CPUs to the host is retaken (up
to as many retakes as pairs asked for), and the own share is given both over the pairs within
the limit (what the aim is judged on) and over every pair taken.

``python -m bench.ownshare FILE.json`` prints the intervals of a suite result file.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from tokenring.perf import (
    STEAL_LIMIT_PCT,
    describe,
    describe_interleaved,
    interval,
    pair_share_us,
    within_steal_limit,
)

#: issue 23's aim: the interval's upper end at most this many µs per hop
OWN_SHARE_AIM_US = 10.0


def own_share(pairs: list[tuple[float, float]], nodes: int) -> dict[str, Any]:
    """The own share per hop (µs) over alternating pairs of (ring, bare) median round trips in ms:
    each pair's share, their mean and 95 % interval, and whether the interval's top meets the aim."""
    shares = [pair_share_us(ring, bare, nodes) for ring, bare in pairs]
    out = interval(shares)
    out["pairs_us"] = [round(x, 2) for x in shares]
    out["aim_us"] = OWN_SHARE_AIM_US
    out["met"] = bool(out["n"] >= 2 and out["hi"] <= OWN_SHARE_AIM_US)
    return out


def more_pairs_needed(taken: int, pairs: int, pair_steal: list[tuple[float, float]]) -> bool:
    """The retake rule: take the ``pairs`` asked for, then more while fewer than ``pairs`` are
    within the steal limit, at most ``2 * pairs`` in all (a pair that failed counts as spoiled)."""
    if taken < pairs:
        return True
    return taken < 2 * pairs and sum(map(within_steal_limit, pair_steal)) < pairs


def screened_pairs(record: dict[str, Any]) -> tuple[int, int, float] | None:
    """(pairs within the steal limit, pairs taken, the limit %) of a scaling record; None for a
    record from before steal was recorded."""
    steal = record.get("pair_steal_pct")
    if not record.get("own_share_all_us") or steal is None:
        return None
    limit = float(record.get("steal_limit_pct", STEAL_LIMIT_PCT))
    return sum(within_steal_limit(pair, limit) for pair in steal), len(steal), limit


def pairs_for(n: int, quick: bool) -> int:
    """Alternating bare/ring pairs per size: on two shared cores a single pair can land in a fast
    or a slow mode (the bare 8-node ring's median moves between 0.6 and 0.8 ms from run to run:
    fast while other work keeps both virtual CPUs busy, slow when they halt between hops), so the
    own share per hop is a mean over pairs with its 95 % interval (:func:`own_share`). Small rings
    take seconds a pair, 64 nodes about 15 s (8 pairs: four gave an interval 18 µs wide), 255
    nodes minutes (255 processes form twice): ten there, as three gave an interval 220 µs wide
    and ten 44 µs."""
    if quick:
        return 2 if n <= 8 else 1
    return 8 if n <= 64 else 10


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        sys.stderr.write("usage: python -m bench.ownshare RESULT.json\n")
        return 2
    try:
        data = json.loads(Path(args[0]).read_text())
    except (OSError, ValueError) as exc:
        sys.stderr.write(f"{args[0]}: cannot read a suite result: {exc}\n")
        return 2
    runs = data.get("sections", {}).get("scaling", {}).get("runs", [])
    shown = 0
    for record in runs:
        share = record.get("own_share_us")
        if share:
            load = record.get("load_before", [None])[0]
            line = f"{record['topology']:6} {record['nodes']:3} nodes: {describe(share)}, load {load}"
            screened = screened_pairs(record)
            if screened:
                calm, taken, limit = screened
                every = describe(record["own_share_all_us"])
                line += f"; {calm} of {taken} pairs within {limit:.0f} % steal, every pair: {every}"
            print(line)
            shown += 1
        if record.get("interleaved"):
            print(f"interleaved windows, {describe_interleaved(record['interleaved'])}")
            shown += 1
    if not shown:
        sys.stderr.write(f"{args[0]}: no own share per hop in its scaling section\n")
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
