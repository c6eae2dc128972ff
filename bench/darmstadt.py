"""The Darmstadt sensors beside the seed's figures (seed 000, chapter 10): ``python -m bench.darmstadt``.

Each figure over several world seeds, without the ring (the sensor models alone: seconds; the
odometry drive: about a minute per seed):

* the gyroscope at rest for the seed's 200 s (figures 10.2 and 10.4): how quantised its raw
  values are (the share of the commonest value, the values seen), how far its zero point moved,
  and the orientation summed from its rates after the module's 100-sample calibration;
* LOPS on the seed's drive, three laps of a 3 m square in the square hall (figures 10.6, 10.7):
  the share of measurements without a position (seed: 404 of 2024) and how many of those had
  one receiver wrong, the positions' error against the true path;
* LOPS's cycle on the robot over the WLAN model (chapter 10: 11–270 ms, over 85 % in 90–110 ms);
* odometry on the seed's drive in the Darmstadt hall (``darmstadt-hall``: the square hall, its
  floor calibrated to this figure): the robot's own action navigator drives three laps of the 3 m
  square without the ring (:mod:`modules.sim.drivesim`), and dead reckoning's end error over the
  drive alone (its path re-anchored on the truth at the drive's start, as ``bench.localization``
  does) stands beside the seed's "more than 150 cm" (chapter 10);
* the synchronisation by odometry count 1 (chapter 10: 95–105 ms, over 85 % within 98–102 ms),
  copied from the newest ``bench/results/syncregular-*.json`` of ``python -m bench.syncregular
  --modes ours,sip,darmstadt --triggers seedcount --arrival --json ...`` (a ring benchmark: run
  apart) when there is one.

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
    "odometry_end": "more than 1500 mm",
    "sync_cycle": "95–105 ms, over 85 % within 98–102 ms",
}
#: the seed's hall with the floor calibrated to its odometry figure, and the seed's drive
HALL = "darmstadt-hall"
SQUARE_DRIVE = Path(__file__).resolve().parent.parent / "actions" / "square-3-laps.act"
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


def odometry_seed_drive(seed: int, world: str = HALL) -> dict[str, Any]:
    """Chapter 10's three laps in ``world``, driven by main's action navigator without the ring:
    dead reckoning's end error and heading error over the drive alone."""
    from modules.sim.drivesim import DriveSim, repository_config

    sim = DriveSim(world, seed, SQUARE_DRIVE.read_text(), repository_config(world))
    result = sim.drive()
    start_ms = getattr(sim, "drive_start_ms", 0.0)
    return {
        "seed": seed,
        **drive_alone(result["positions"]["O"], result["truth"], start_ms),
        "finished": result["finished"],
    }


def drive_alone(
    rows: list[tuple[int, dict[str, Any]]], truth: np.ndarray, start_ms: float
) -> dict[str, float]:
    """End error of a path of position records (stamp, {x, y, psi}) from ``start_ms`` on, the path
    re-anchored on the truth (rows t, x, y, θ) at its first record there by a rigid transform."""
    after = [(stamp, p) for stamp, p in rows if stamp >= start_ms]
    (t0, first), (t_end, last) = after[0], after[-1]
    t, theta = truth[:, 0], np.unwrap(truth[:, 3])
    rot = float(np.interp(t0, t, theta)) - first["psi"]
    c, s = math.cos(rot), math.sin(rot)
    dx, dy = last["x"] - first["x"], last["y"] - first["y"]
    ex = float(np.interp(t0, t, truth[:, 1])) + c * dx - s * dy
    ey = float(np.interp(t0, t, truth[:, 2])) + s * dx + c * dy
    heading = math.remainder(last["psi"] + rot - float(np.interp(t_end, t, theta)), 2 * math.pi)
    return {
        "end_error_mm": math.hypot(
            ex - float(np.interp(t_end, t, truth[:, 1])), ey - float(np.interp(t_end, t, truth[:, 2]))
        ),
        "heading_error_deg": math.degrees(heading),
    }


def spread(values: list[float]) -> dict[str, float]:
    """Median and extremes over the seeds."""
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def sync_regularity(results: Path = RESULTS) -> dict[str, Any] | None:
    """The seed's count trigger online from the newest ``syncregular-*.json`` (``bench.syncregular``
    on the ring): per mode its share of periods within 98–102 and 95–105 ms, in sensor time and
    in arrival time, medians over the runs with the runs' extremes. None: no such file."""
    files = sorted(results.glob("syncregular-*.json"))
    if not files:
        return None
    data = json.loads(files[-1].read_text())
    keys = (
        "mode", "runs", "median_period_ms", "within_98_102ms", "within_98_102ms_range", "within_95_105ms",
        "arrival_median_ms", "arrival_98_102ms", "arrival_98_102ms_range", "arrival_95_105ms", "load",
    )  # fmt: skip
    lines = [
        {key: t.get(key) for key in keys}
        for t in data.get("table", [])
        if t.get("trigger") == "seedcount" and t.get("source") == "online"
    ]
    return {"file": files[-1].name, "speed": data.get("speed"), "lines": lines} if lines else None


#: the parts by their short names (``--parts``): the summary's key and the measurement per seed
PARTS = {
    "gyro": "gyro_at_rest",
    "lops": "lops_seed_drive",
    "cycle": "lops_cycle",
    "odometry": "odometry_seed_drive",
}


def run(
    seeds: list[int], say: Any = print, jobs: int = 1, parts: tuple[str, ...] = tuple(PARTS)
) -> dict[str, Any]:
    """Every figure of ``parts`` for every seed, and its spread over them (``jobs``: seeds
    measured at once)."""
    from concurrent.futures import ProcessPoolExecutor

    out: dict[str, Any] = {
        "benchmark": "darmstadt",
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "seeds": seeds,
    }
    out["seed_figures"] = SEED
    chosen = [(PARTS[part], globals()[PARTS[part]]) for part in parts]
    for i, (name, measure) in enumerate(chosen, 1):
        say(f"[{i}/{len(chosen)}] {name.replace('_', ' ')}, seeds {', '.join(map(str, seeds))} ...")
        if jobs > 1:
            with ProcessPoolExecutor(max_workers=jobs) as pool:
                records = list(pool.map(measure, seeds))
        else:
            records = [measure(seed) for seed in seeds]
        keys = [k for k, v in records[0].items() if k != "seed" and isinstance(v, int | float)]
        out[name] = {
            "runs": records,
            "spread": {k: spread([float(r[k]) for r in records if r[k] is not None]) for k in keys},
        }
    if "odometry_seed_drive" in out:
        out["odometry_seed_drive"]["world"] = HALL
    sync = sync_regularity()
    if sync is not None:
        out["sync_regularity"] = sync
    return out


def main(argv: list[str] | None = None) -> int:
    from tokenring.cli import OneLineParser

    parser = OneLineParser(
        prog="python -m bench.darmstadt",
        description="The Darmstadt sensors (gyroscope, LOPS), odometry in the Darmstadt hall and the "
        "synchronisation beside seed 000's chapter-10 figures.",
    )
    parser.add_argument("--seeds", default="1,2,3", help="world seeds, comma-separated (default %(default)s)")
    parser.add_argument(
        "--json", metavar="FILE", help="the summary's file (default bench/results/darmstadt-DATE.json)"
    )
    parser.add_argument("--force", action="store_true", help="replace an existing --json file")
    parser.add_argument("--jobs", type=int, default=1, help="seeds measured at once (default %(default)s)")
    parser.add_argument(
        "--parts",
        default=",".join(PARTS),
        help="which figures: of gyro, lops, cycle, odometry (default all; odometry takes about a minute per seed)",
    )
    args = parser.parse_args(argv)
    parts = tuple(p.strip() for p in args.parts.split(",") if p.strip())
    if not parts or any(p not in PARTS for p in parts):
        parser.error(f"--parts {args.parts!r}: give some of {', '.join(PARTS)}")
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    except ValueError:
        parser.error(f"--seeds {args.seeds!r}: give whole numbers, e.g. 1,2,3")
    if not seeds or any(not 0 <= s < 2**32 for s in seeds):
        parser.error(f"--seeds {args.seeds!r}: one or more seeds in 0..{2**32 - 1}")
    target = Path(args.json) if args.json else RESULTS / f"darmstadt-{time.strftime('%Y-%m-%d')}.json"
    if target.exists() and not args.force:
        parser.error(f"--json {target}: exists (give --force to replace it)")
    result = run(
        seeds, say=lambda line: print(line, file=sys.stderr, flush=True), jobs=max(1, args.jobs), parts=parts
    )
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(result, indent=1) + "\n")
    print(section_md(result, target.name))
    return 0


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def section_md(result: dict[str, Any], name: str) -> str:
    """RESULTS.md's section from one summary: ours per figure, median (min–max) over the seeds,
    beside the seed's (the parts the summary holds)."""
    seeds = ", ".join(map(str, result["seeds"]))

    def rng(s: dict[str, float], fmt: Any = lambda v: f"{v:.1f}") -> str:
        return f"{fmt(s['median'])} ({fmt(s['min'])}–{fmt(s['max'])})"

    rows = sensor_rows(result, rng) + odometry_rows(result, rng) + sync_rows(result)
    table = "\n".join(f"| {a} | {b} | {s} |" for a, b, s in rows)
    odometry = (
        f"; the odometry drive by main's action navigator without the ring in `{result['odometry_seed_drive'].get('world', HALL)}`"
        if "odometry_seed_drive" in result
        else ""
    )
    return (
        "## The Darmstadt sensors beside the seed (`python -m bench.darmstadt`)\n\n"
        f"Generated from [{name}](results/{name}) (do not edit): the sensor models alone{odometry}, world seeds {seeds}, "
        "each figure as the median over the seeds with its extremes; the seed's figures from seed 000 "
        "chapter 10 ([docs/darmstadt-sensors.md](../docs/darmstadt-sensors.md)).\n\n"
        "| figure | ours: median (min–max) | seed 000 |\n|---|---|---|\n" + table + "\n"
    )


def sensor_rows(result: dict[str, Any], rng: Any) -> list[tuple[str, str, str]]:
    """The gyroscope's and LOPS's rows (those the summary holds)."""
    if not all(k in result for k in ("gyro_at_rest", "lops_seed_drive", "lops_cycle")):
        return []
    g, lo, c = (result[k]["spread"] for k in ("gyro_at_rest", "lops_seed_drive", "lops_cycle"))
    return [
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


def odometry_rows(result: dict[str, Any], rng: Any) -> list[tuple[str, str, str]]:
    """The odometry drive's rows (none in a summary from before it was measured)."""
    odometry = result.get("odometry_seed_drive")
    if not odometry:
        return []
    o, hall = odometry["spread"], odometry.get("world", HALL)
    return [
        (f"odometry only, 3 laps of the 3 m square in `{hall}`: end error (mm)", rng(o["end_error_mm"], lambda v: f"{v:.0f}"), SEED["odometry_end"]),
        ("… its heading off at the end (°)", rng(o["heading_error_deg"], lambda v: f"{v:+.0f}"), ""),
    ]  # fmt: skip


def sync_rows(result: dict[str, Any]) -> list[tuple[str, str, str]]:
    """The synchronisation's rows, from the ring benchmark's file copied into the summary."""
    sync = result.get("sync_regularity")
    if not sync:
        return []
    what = {
        "ours": "the motor's counters every loop tick",
        "seed": "the seed's modules, counters every loop tick",
        "sip": "the motor's SIPs, every 100 ms of its clock",
        "darmstadt": "`up --sensors darmstadt` (the SIPs and the Darmstadt sensors)",
    }
    rows = []
    order = list(what)
    for line in sorted(
        sync["lines"], key=lambda x: order.index(x["mode"]) if x["mode"] in order else len(order)
    ):
        span = line.get("within_98_102ms_range") or [line["within_98_102ms"]] * 2
        arrival = line.get("arrival_98_102ms")
        arrival_span = line.get("arrival_98_102ms_range") or [arrival] * 2
        load = f", load avg {line['load'][0]:.1f}–{line['load'][1]:.1f}" if line.get("load") else ""
        rows.append(
            (
                f"synchronisation by odometry count 1 on the ring, {what.get(line['mode'], line['mode'])} "
                f"({line['runs']} runs at speed-up {sync['speed']}{load}; [{sync['file']}](results/{sync['file']})): "
                "within 98–102 ms of sensor time / of arrival time",
                f"{_pct(line['within_98_102ms'])} ({_pct(span[0])}–{_pct(span[1])}) / "
                + (
                    "–"
                    if arrival is None
                    else f"{_pct(arrival)} ({_pct(arrival_span[0])}–{_pct(arrival_span[1])})"
                ),
                SEED["sync_cycle"],
            )
        )
    return rows


if __name__ == "__main__":
    sys.exit(main())
