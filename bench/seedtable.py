"""The 2001 robot beside ours: the seeds' documented figures reproduced on the emulator, in one run.

    python -m bench.seedtable            # about an hour; writes bench/results/seedmode-DATE.json
                                         # and rebuilds bench/RESULTS.md's section from it

Parts (``--parts``; a part not run is carried over from the latest earlier result file):

* ``classifier`` — seed 001 §4.3.2's behaviour table through the seed's classifier and ours;
* ``roundtrip``  — the seed's seven computers at its pace (``--profile arcnet``), programs
  running with ``--algorithms seed`` and ``ours`` (seed: 30-40 ms);
* ``maps``       — ``tokenring up --explore 2`` with the two robots and each part (module or
  body) switched to the seed's alone (:mod:`bench.seedmode`), world seeds 1-3: coverage,
  precision, corners closed, the map's orientation error early and late in the drive (seed:
  corners missing, a growing angle error) and the robot's end pose error;
* ``darmstadt``  — seed 000's experiment (3 laps of the 3 m square, :mod:`bench.localization`)
  with ``ours`` and with the seed's robot carrying the Darmstadt filter (``seed,copro=ours``):
  dead reckoning and filter end errors (seed: > 1500 mm and ≈ 300 mm) and the synchronisation's
  regularity (seed: 95-105 ms, 85 % of cycles within 98-102 ms).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from bench.seedreport import fmt, latest, section_md

HERE = Path(__file__).resolve().parent
PARTS = ("classifier", "roundtrip", "maps", "darmstadt")
#: seed 001 §4.3.2's behaviour table: its readings and the behaviours the seed's function gives
SEED_TABLE = [30, 32, 34, 50, 50, 50]
SEED_TABLE_BEHAVIOURS = ["NONE", "NONE", "LINEAR", "DEGRESSIVE", "PROGRESSIVE", "LINEAR"]
DARMSTADT_CONFIGS = ("ours", "seed,copro=ours")

Say = Callable[[str], None]


@contextlib.contextmanager
def algorithms_env(value: str) -> Iterator[None]:
    """Every program started inside runs ``--algorithms value`` (the variable `up` sets for them)."""
    from modules.variants import ENV

    before = os.environ.get(ENV)
    os.environ[ENV] = value
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(ENV, None)
        else:
            os.environ[ENV] = before


def part_classifier(args: argparse.Namespace, say: Say) -> dict[str, Any]:
    from modules.sensors.sonar import make_classifier

    names = ["NONE", "LINEAR", "PROGRESSIVE", "DEGRESSIVE"]  # protocol.yaml's enums.behaviour
    out: dict[str, Any] = {"readings_cm": SEED_TABLE, "seed_documented": SEED_TABLE_BEHAVIOURS}
    for mode in ("seed", "ours"):
        classifier = make_classifier(mode == "seed")
        out[mode] = [names[classifier.observe(cm)] for cm in SEED_TABLE]
    say(f"classifier: seed {out['seed']}, ours {out['ours']}")
    return out


def part_roundtrip(args: argparse.Namespace, say: Say) -> dict[str, Any]:
    from bench.suite import SEED_NODES, load_avg, node_store, robot_plans, world_plan
    from tokenring.perf import run_ring, summarize

    runs = []
    for config in ("seed", "ours"):
        say(f"round trip: the seed's {len(SEED_NODES)} computers at --profile arcnet, --algorithms {config}")
        ring = f"seedrt{os.getpid()}{config}"
        with algorithms_env(config), node_store() as store:
            run = run_ring(
                len(SEED_NODES), args.rounds, 120, bitrate="2.5M", profile="arcnet", timeout=300.0,
                plans=robot_plans(SEED_NODES, True), services=[world_plan(ring)], ring=ring,
                extra_node_args=store,
            )  # fmt: skip
        rtt = summarize(run.rounds_s)  # (in ms)
        record = {
            "algorithms": config,
            "rounds": len(run.rounds_s),
            "median_ms": rtt["median"],
            "p10_ms": float(np.percentile(run.rounds_s, 10)) * 1e3,
            "p90_ms": rtt["p90"],
            "p99_ms": rtt["p99"],
            "load": load_avg(),
        }
        say(f"  median {record['median_ms']:.1f} ms, p90 {record['p90_ms']:.1f} ms")
        runs.append(record)
    return {"nodes": len(SEED_NODES), "runs": runs}


def part_maps(args: argparse.Namespace, say: Say) -> dict[str, Any]:
    from bench.closedloop import parse_seeds
    from bench.seedmode import CONFIGS, explore, summarize

    rooms = args.rooms.split(",")
    seeds = parse_seeds(args.seeds)
    jobs = [(room, seed, config) for room in rooms for seed in seeds for config in CONFIGS]
    rows = []
    with tempfile.TemporaryDirectory(prefix="tokenring-seedtable-") as tmp:
        for i, (room, seed, config) in enumerate(jobs, 1):
            say(f"maps [{i}/{len(jobs)}]: {room}, world seed {seed}, --algorithms {config}")
            rows.append(explore(room, seed, config, args.speed, args.minutes, Path(tmp), args.bitrate))
    tables = {room: summarize([r for r in rows if r["world"] == room]) for room in rooms}
    return {
        "speed": args.speed,
        "bitrate": args.bitrate,
        "minutes": args.minutes,
        "seeds": seeds,
        "runs": rows,
        "tables": tables,
    }


def part_darmstadt(args: argparse.Namespace, say: Say) -> dict[str, Any]:
    from bench.closedloop import parse_seeds
    from bench.localization import run_experiment

    runs = []
    for config in DARMSTADT_CONFIGS:
        for seed in parse_seeds(args.darmstadt_seeds):
            say(f"darmstadt: 3 laps of the 3 m square, world seed {seed}, --algorithms {config}")
            with tempfile.TemporaryDirectory(prefix="tokenring-seedtable-") as tmp, algorithms_env(config):
                result = run_experiment(seed, workdir=Path(tmp), say=lambda _m: None)
            sources = result.get("sources", {})  # `tokenring analyze` of the Localizer's data log
            sync = result.get("sync", {})
            record: dict[str, Any] = {
                "algorithms": config,
                "seed": seed,
                "dead_reckoning_mm": sources.get("O", {}).get("end_error_mm"),
                "filter_mm": sources.get("K", {}).get("end_error_mm"),
                "filter_rmse_mm": sources.get("K", {}).get("rmse_mm"),
                "sync": {  # (analyze counts the shares as the seed states them, seed 000 §10)
                    "median_ms": sync.get("median_period_ms"),
                    "p99_ms": sync.get("p99_period_ms"),
                    "within_98_102": sync.get("within_98_102ms"),
                    "within_95_105": sync.get("within_95_105ms"),
                },
            }
            say(
                f"  dead reckoning {fmt(record['dead_reckoning_mm'], 0)} mm, filter {fmt(record['filter_mm'])} mm, "
                f"sync median {fmt(record['sync']['median_ms'])} ms"
            )
            runs.append(record)
    return {"runs": runs}


PART_FUNCTIONS: dict[str, Callable[[argparse.Namespace, Say], dict[str, Any]]] = {
    "classifier": part_classifier,
    "roundtrip": part_roundtrip,
    "maps": part_maps,
    "darmstadt": part_darmstadt,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.seedtable",
        description=__doc__.split("\n\n")[0],
        epilog="examples:\n  python -m bench.seedtable\n  python -m bench.seedtable --parts maps --rooms square --seeds 1-3",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--parts", default=",".join(PARTS), help="comma-separated (default: all)")
    parser.add_argument("--rooms", default="square,office", help="rooms for the maps (default %(default)s)")
    parser.add_argument(
        "--seeds", default="1-3", help="world seeds for the maps: 1 or 1,2 or 1-3 (default 1-3)"
    )
    parser.add_argument("--speed", default="10", help="the world's speed-up for the maps (default 10)")
    parser.add_argument("--bitrate", default="max", help="the ring's bitrate for the maps (default max)")
    parser.add_argument("--minutes", type=float, default=20.0, help="emulated minutes per map (default 20)")
    parser.add_argument(
        "--rounds", type=int, default=600, help="round trips measured per robot (default 600)"
    )
    parser.add_argument(
        "--darmstadt-seeds", default="1-3", help="world seeds of the square laps (default 1-3)"
    )
    parser.add_argument(
        "--out", default=str(HERE / "results"), help="results directory (default bench/results)"
    )
    parser.add_argument("--no-report", action="store_true", help="do not rebuild bench/RESULTS.md")
    args = parser.parse_args(argv)
    chosen = [p.strip() for p in args.parts.split(",") if p.strip()]
    unknown = [p for p in chosen if p not in PARTS]
    if unknown:
        parser.error(f"--parts: unknown {', '.join(unknown)} (known: {', '.join(PARTS)})")
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"seedmode-{datetime.date.today().isoformat()}.json"

    def say(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    started = time.monotonic()
    parts: dict[str, Any] = {}
    for name in chosen:
        parts[name] = PART_FUNCTIONS[name](args, say)
    if path.exists():  # an earlier run today: the parts not run now stay in its file
        with contextlib.suppress(OSError, ValueError):
            parts = {**json.loads(path.read_text()).get("parts", {}), **parts}
    record = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "command": "python -m bench.seedtable " + " ".join(argv if argv is not None else sys.argv[1:]),
        "seconds": round(time.monotonic() - started),
        "load_end": [round(x, 2) for x in os.getloadavg()],
        "parts": parts,
    }
    path.write_text(json.dumps(record, indent=1) + "\n")
    say(f"written {path}")
    print(section_md(latest(out_dir)))
    if not args.no_report:  # (bench.report renders this section: no import back to it)
        return subprocess.run(
            [sys.executable, "-m", "bench.report", "--out", str(out_dir)], check=False
        ).returncode
    return 0


if __name__ == "__main__":
    sys.exit(main())
