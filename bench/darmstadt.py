"""The Darmstadt sensors beside the seed's figures (seed 000, chapter 10): ``python -m bench.darmstadt``.

Each figure over several world seeds, from the sensor models alone (no ring: seconds, not minutes):

* the gyroscope at rest for the seed's 200 s (figures 10.2 and 10.4): how quantised its raw
  values are (the share of the commonest value, the values seen), how far its zero point moved,
  and the orientation summed from its rates after the module's 100-sample calibration;
* LOPS on the seed's drive, three laps of a 3 m square in the square hall (figures 10.6, 10.7):
  the share of measurements without a position (seed: 404 of 2024) and how many of those had
  one receiver wrong, the positions' error against the true path;
* LOPS's cycle on the robot over the WLAN model (chapter 10: 11–270 ms, over 85 % in 90–110 ms).

The summary goes to ``bench/results/darmstadt-<date>.json`` (``--json`` for another file);
``python -m bench.report`` renders its section of RESULTS.md from the newest.
"""

from __future__ import annotations

import json
import math
import statistics
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).with_name("results")
#: the seed's own figures, as chapter 10 gives them
SEED = {
    "lops_without_position": "404 of 2024 (20.0 %)",
    "lops_noise": "about ±1 cm (figures 10.6, 10.7)",
    "lops_cycle": "11–270 ms, over 85 % within 90–110 ms",
    "gyro_rest": "one value with the next bit now and then (figure 10.2); drift minimal over 200 s (figure 10.4)",
}
GYRO_PERIOD_MS = 20.48
REST_S = 200.0
CALIBRATION_SAMPLES = 100


def gyro_at_rest(seed: int) -> dict[str, Any]:
    """200 s of raw values at rest from the world's gyro model, judged as the module would."""
    from modules.world.gyroscope import SCALE_RAD_S, RateGyro, gyro_rng

    gyro = RateGyro(gyro_rng(seed))
    n = int(REST_S * 1000 / GYRO_PERIOD_MS)
    raw = np.array([gyro.sample(k * GYRO_PERIOD_MS, 0.0) for k in range(n)], dtype=float)
    mode, count = Counter(raw.tolist()).most_common(1)[0]
    zero = float(raw[:CALIBRATION_SAMPLES].mean())  # the module's calibration
    angle_rad = float(np.sum((raw[CALIBRATION_SAMPLES:] - zero) * SCALE_RAD_S * GYRO_PERIOD_MS / 1000.0))
    return {
        "seed": seed,
        "samples": n,
        "commonest_share": count / n,
        "within_one_count": float(np.mean(np.abs(raw - mode) <= 1)),
        "values_seen": len(set(raw.tolist())),
        "zero_moved_counts": float(raw[-CALIBRATION_SAMPLES:].mean() - zero),
        "angle_after_200s_deg": math.degrees(angle_rad),
    }


def lops_seed_drive(seed: int) -> dict[str, Any]:
    """Chapter 10's three laps with LOPS measuring every 98 ms."""
    from modules.description import load_world
    from modules.lops.config import for_world
    from modules.lops.mcu import OK
    from modules.lops.system import LopsSystem, seed_drive, simulate

    world = load_world("square")
    system = LopsSystem(world, for_world(world), seed=seed)
    path, total_ms = seed_drive()
    run = simulate(system, path, int(total_ms // 98.0))
    without = [sent for _, sent in run if sent.measurement.position is None]
    one_wrong = sum(1 for sent in without if sum(k != OK for k in sent.reading.kinds) == 1)
    errors = np.array([math.dist(p, s.measurement.position) for p, s in run if s.measurement.position])
    return {
        "seed": seed,
        "measurements": len(run),
        "without_position": len(without),
        "without_share": len(without) / len(run),
        "one_receiver_wrong_share": one_wrong / len(without) if without else None,
        "error_median_mm": float(np.median(errors)),
        "error_p95_mm": float(np.percentile(errors, 95)),
        "restarts": system.lopscpp.filter.restarts,
    }


def lops_cycle(seed: int, packets: int = 50_000) -> dict[str, Any]:
    """The time between packets on the robot, from the WLAN model at 98 ms triggers."""
    from modules.lops.wlan import WlanLink, cycle_summary, cycles

    link = WlanLink(seed=seed)
    return {"seed": seed, **cycle_summary(cycles(link.deliver(k * 98.0) for k in range(packets)))}


def spread(values: list[float]) -> dict[str, float]:
    """Median and extremes over the seeds."""
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def run(seeds: list[int], say: Any = print) -> dict[str, Any]:
    """Every figure for every seed, and its spread over them."""
    out: dict[str, Any] = {
        "benchmark": "darmstadt",
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "seeds": seeds,
    }
    out["seed_figures"] = SEED
    parts = (("gyro_at_rest", gyro_at_rest), ("lops_seed_drive", lops_seed_drive), ("lops_cycle", lops_cycle))
    for i, (name, measure) in enumerate(parts, 1):
        say(f"[{i}/{len(parts)}] {name.replace('_', ' ')}, seeds {', '.join(map(str, seeds))} ...")
        records = [measure(seed) for seed in seeds]
        keys = [k for k, v in records[0].items() if k != "seed" and isinstance(v, int | float)]
        out[name] = {
            "runs": records,
            "spread": {k: spread([float(r[k]) for r in records if r[k] is not None]) for k in keys},
        }
    return out


def main(argv: list[str] | None = None) -> int:
    from tokenring.cli import OneLineParser

    parser = OneLineParser(
        prog="python -m bench.darmstadt",
        description="The Darmstadt sensors (gyroscope, LOPS) beside seed 000's chapter-10 figures.",
    )
    parser.add_argument("--seeds", default="1,2,3", help="world seeds, comma-separated (default %(default)s)")
    parser.add_argument(
        "--json", metavar="FILE", help="the summary's file (default bench/results/darmstadt-DATE.json)"
    )
    parser.add_argument("--force", action="store_true", help="replace an existing --json file")
    args = parser.parse_args(argv)
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    except ValueError:
        parser.error(f"--seeds {args.seeds!r}: give whole numbers, e.g. 1,2,3")
    if not seeds or any(not 0 <= s < 2**32 for s in seeds):
        parser.error(f"--seeds {args.seeds!r}: one or more seeds in 0..{2**32 - 1}")
    target = Path(args.json) if args.json else RESULTS / f"darmstadt-{time.strftime('%Y-%m-%d')}.json"
    if target.exists() and not args.force:
        parser.error(f"--json {target}: exists (give --force to replace it)")
    result = run(seeds, say=lambda line: print(line, file=sys.stderr, flush=True))
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(result, indent=1) + "\n")
    print(section_md(result, target.name))
    return 0


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def section_md(result: dict[str, Any], name: str) -> str:
    """RESULTS.md's section from one summary: ours per figure, median (min–max) over the seeds,
    beside the seed's."""
    g, lo, c = (result[k]["spread"] for k in ("gyro_at_rest", "lops_seed_drive", "lops_cycle"))
    seeds = ", ".join(map(str, result["seeds"]))

    def rng(s: dict[str, float], fmt: Any = lambda v: f"{v:.1f}") -> str:
        return f"{fmt(s['median'])} ({fmt(s['min'])}–{fmt(s['max'])})"

    rows = [
        ("gyroscope at rest, 200 s: share of the commonest raw value", rng(g["commonest_share"], _pct), SEED["gyro_rest"]),
        ("gyroscope at rest: raw values within one count of it", rng(g["within_one_count"], _pct), ""),
        ("gyroscope at rest: zero point moved (counts, last 2 s − calibration)", rng(g["zero_moved_counts"], lambda v: f"{v:+.2f}"), ""),
        ("gyroscope at rest: orientation summed after calibration (°)", rng(g["angle_after_200s_deg"], lambda v: f"{v:+.2f}"), ""),
        ("LOPS, 3 laps of the 3 m square: measurements without a position", rng(lo["without_share"], _pct), SEED["lops_without_position"]),
        ("… of those, one receiver wrong", rng(lo["one_receiver_wrong_share"], _pct), "mostly one receiver wrong"),
        ("LOPS position error, median / p95 (mm)", f"{rng(lo['error_median_mm'])} / {rng(lo['error_p95_mm'])}", SEED["lops_noise"]),
        ("LOPS cycle on the robot: min / max (ms)", f"{rng(c['min_ms'])} / {rng(c['max_ms'])}", "11 / 270"),
        ("LOPS cycle: within 90–110 ms", rng(c["within_90_110"], _pct), "over 85 %"),
    ]  # fmt: skip
    table = "\n".join(f"| {a} | {b} | {s} |" for a, b, s in rows)
    return (
        "## The Darmstadt sensors beside the seed (`python -m bench.darmstadt`)\n\n"
        f"Generated from [{name}](results/{name}) (do not edit): the sensor models alone, world seeds {seeds}, "
        "each figure as the median over the seeds with its extremes; the seed's figures from seed 000 "
        "chapter 10 ([docs/darmstadt-sensors.md](../docs/darmstadt-sensors.md)).\n\n"
        "| figure | ours: median (min–max) | seed 000 |\n|---|---|---|\n" + table + "\n"
    )


if __name__ == "__main__":
    sys.exit(main())
