"""The 2001 robot beside ours: the seeds' documented figures reproduced on the emulator, in one run.

    python -m bench.seedtable            # about 40 minutes; writes bench/results/seedmode-DATE.json
                                         # and rebuilds bench/RESULTS.md's section from it

Parts (``--parts``; a part not run is carried over from the latest earlier result file):

* ``classifier`` — seed 001 §4.3.2's behaviour table through the seed's classifier and ours;
* ``roundtrip``  — the seed's seven computers at its pace (``--profile arcnet``), programs
  running with ``--algorithms seed`` and ``ours`` (seed: 30-40 ms);
* ``maps``       — ``tokenring up --explore 2`` with the two robots and each module switched to
  the seed's alone (:mod:`bench.seedmode`): coverage, precision, corners closed and the map's
  orientation error early and late in the drive (seed: corners missing, a growing angle error);
* ``darmstadt``  — seed 000's experiment (3 laps of the 3 m square, :mod:`bench.localization`)
  with ``ours`` and with the seed's robot carrying the Darmstadt filter (``seed,copro=ours``):
  dead reckoning and filter end errors (seed: > 1500 mm and ≈ 300 mm) and the synchronisation's
  regularity (seed: 95-105 ms, 85 % of cycles within 98-102 ms).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import itertools
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
PARTS = ("classifier", "roundtrip", "maps", "darmstadt")
#: seed 001 §4.3.2's behaviour table: its readings and the behaviours the seed's function gives
SEED_TABLE = [30, 32, 34, 50, 50, 50]
SEED_TABLE_BEHAVIOURS = ["NONE", "NONE", "LINEAR", "DEGRESSIVE", "PROGRESSIVE", "LINEAR"]
DARMSTADT_CONFIGS = ("ours", "seed,copro=ours")
SEED_FIGURES = {
    "roundtrip_ms": "30-40",
    "odometry_mm": "> 1500",
    "filter_mm": "≈ 300",
    "sync": "95-105 ms, 85 % within 98-102 ms",
}

Say = Callable[[str], None]


@contextlib.contextmanager
def algorithms_env(value: str) -> Iterator[None]:
    """Every program started inside runs ``--algorithms value`` (the variable `up` sets for them)."""
    from modules.common.algorithms import ENV

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
    from modules.common.sonar import make_classifier

    names = ["NONE", "LINEAR", "PROGRESSIVE", "DEGRESSIVE"]  # protocol.yaml's enums.behaviour
    out: dict[str, Any] = {"readings_cm": SEED_TABLE, "seed_documented": SEED_TABLE_BEHAVIOURS}
    for mode in ("seed", "ours"):
        classifier = make_classifier(mode == "seed")
        out[mode] = [names[classifier.observe(cm)] for cm in SEED_TABLE]
    say(f"classifier: seed {out['seed']}, ours {out['ours']}")
    return out


def part_roundtrip(args: argparse.Namespace, say: Say) -> dict[str, Any]:
    from bench.suite import SEED_NODES, load_avg, node_store, robot_plans, world_plan
    from tokenring.roundtrip import run_ring, summarize

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
        rtt = summarize(run.rounds_s)
        record = {
            "algorithms": config,
            "rounds": len(run.rounds_s),
            "median_ms": rtt["median"] * 1e3,
            "p10_ms": float(np.percentile(run.rounds_s, 10)) * 1e3,
            "p90_ms": float(np.percentile(run.rounds_s, 90)) * 1e3,
            "p99_ms": rtt["p99"] * 1e3,
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
            rows.append(explore(room, seed, config, args.speed, args.minutes, Path(tmp)))
    tables = {room: summarize([r for r in rows if r["world"] == room]) for room in rooms}
    return {"speed": args.speed, "minutes": args.minutes, "seeds": seeds, "runs": rows, "tables": tables}


def sync_figures(periods_ms: list[float]) -> dict[str, float | None]:
    """The synchronisation's regularity as the seed states it: median, p99 and the share of
    cycles within 98-102 ms and within 95-105 ms."""
    p = np.asarray(periods_ms, float)
    if not len(p):
        return {"median_ms": None, "p99_ms": None, "within_98_102": None, "within_95_105": None}
    return {
        "median_ms": float(np.median(p)),
        "p99_ms": float(np.percentile(p, 99)),
        "within_98_102": float(np.mean((p >= 98) & (p <= 102))),
        "within_95_105": float(np.mean((p >= 95) & (p <= 105))),
    }


def sync_periods(log_path: Path) -> list[float]:
    """The periods (ms of sensor time) between the synchronisations a data log recorded."""
    from modules.common.logs import read_log

    stamps = [int(r[0]) for r in read_log(log_path).records if r[1] == "S" and r[2] == "S"]
    return [float(b - a) for a, b in itertools.pairwise(stamps)]


def part_darmstadt(args: argparse.Namespace, say: Say) -> dict[str, Any]:
    from bench.closedloop import parse_seeds
    from bench.localization import run_experiment

    runs = []
    for config in DARMSTADT_CONFIGS:
        for seed in parse_seeds(args.darmstadt_seeds):
            say(f"darmstadt: 3 laps of the 3 m square, world seed {seed}, --algorithms {config}")
            with tempfile.TemporaryDirectory(prefix="tokenring-seedtable-") as tmp, algorithms_env(config):
                result = run_experiment(seed, workdir=Path(tmp), say=lambda _m: None)
                logs = sorted(Path(tmp).rglob("*.trlog"))
                periods = sync_periods(max(logs, key=lambda p: p.stat().st_size)) if logs else []
            record: dict[str, Any] = {
                "algorithms": config,
                "seed": seed,
                "dead_reckoning_mm": result.get("dead_reckoning_mm"),
                "filter_mm": result.get("filter_mm"),
                "finished": result.get("finished"),
                "sync": sync_figures(periods),
            }
            say(
                f"  dead reckoning {_f(record['dead_reckoning_mm'], 0)} mm, filter {_f(record['filter_mm'])} mm, "
                f"sync median {_f(record['sync']['median_ms'])} ms"
            )
            runs.append(record)
    return {"runs": runs}


PART_FUNCTIONS: dict[str, Callable[[argparse.Namespace, Say], dict[str, Any]]] = {
    "classifier": part_classifier,
    "roundtrip": part_roundtrip,
    "maps": part_maps,
    "darmstadt": part_darmstadt,
}


def latest(out_dir: Path) -> dict[str, Any]:
    """Each part as the latest ``seedmode-*.json`` in ``out_dir`` holding it has it (with that
    file's name): a run of some parts leaves the others as they were measured."""
    parts: dict[str, Any] = {}
    for path in sorted(out_dir.glob("seedmode-*.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        for name, part in data.get("parts", {}).items():
            parts[name] = {**part, "file": path.name}
    return parts


# -- the section of bench/RESULTS.md ------------------------------------------------------------


def _f(x: float | None, digits: int = 1, unit: str = "") -> str:
    return "–" if x is None else f"{x:.{digits}f}{unit}"


def _pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.0f} %"


def _median(values: list[float | None]) -> float | None:
    real = [v for v in values if v is not None]
    return float(np.median(real)) if real else None


def section_md(parts: dict[str, Any]) -> str:
    """The "2001 robot beside ours" section of RESULTS.md from a result file's parts."""
    out = [
        "## The 2001 robot beside ours (`python -m bench.seedtable`)",
        "",
        "Generated by `python -m bench.seedtable` from `bench/results/seedmode-*.json` (do not edit). "
        "`--algorithms seed` runs every module as the Hamburg robot did, flaws included "
        "([docs/seed.md](../docs/seed.md)); the seeds' own figures stand beside ours.",
        "",
    ]
    c = parts.get("classifier")
    if c:
        out += [
            "**The sonar's behaviour table** (seed 001 §4.3.2): one sensor's readings in cm and the "
            "behaviour written after each",
            "",
            "| reading | " + " | ".join(map(str, c["readings_cm"])) + " |",
            "|---|" + "---|" * len(c["readings_cm"]),
            "| seed's table | " + " | ".join(c["seed_documented"]) + " |",
            "| `sonar=seed` | " + " | ".join(c["seed"]) + " |",
            "| ours | " + " | ".join(c["ours"]) + " |",
            "",
            "The seed's flaw: the steady reading after the jump has a large negative second difference "
            "and reads PROGRESSIVE; ours judges it against the readings after the jump.",
            "",
        ]
    r = parts.get("roundtrip")
    if r:
        out += [
            f"**Round trip**, the seed's {r['nodes']} computers at its pace (`--profile arcnet`, "
            "2.5 Mbit/s), world and programs running (seed 001: 30-40 ms):",
            "",
            "| `--algorithms` | median ms | p10-p90 | p99 | load |",
            "|---|---|---|---|---|",
            f"| seed robot (2001) | {SEED_FIGURES['roundtrip_ms']} | | | |",
        ]
        for run in r["runs"]:
            out.append(
                f"| {run['algorithms']} | {_f(run['median_ms'])} | {_f(run['p10_ms'])}-{_f(run['p90_ms'])} "
                f"| {_f(run['p99_ms'])} | {run['load'][0]} |"
            )
        out.append("")
    m = parts.get("maps")
    if m:
        out += [
            f"**Maps**: `tokenring up --explore 2` for {m['minutes']:g} emulated minutes at speed {m['speed']}, "
            f"world seeds {', '.join(map(str, m['seeds']))}; medians. Each row switches the named module "
            "to the seed's alone; `angle early → late` is the map's orientation error over its first and "
            "last third of vectors (the seed: corners not recorded, an angle error growing with the drive).",
            "",
        ]
        for room, table in m["tables"].items():
            out += [
                f"*{room}*",
                "",
                "| `--algorithms` | runs | coverage | precision | orientation ° | corners closed | angle early → late ° |",
                "|---|---|---|---|---|---|---|",
            ]
            for t in table:
                failed = f" ({t['failed']} failed)" if t["failed"] else ""
                corners = (
                    "–"
                    if t["corners_closed"] is None
                    else f"{t['corners_closed']:.0f}/{t['corners_total']:.0f}"
                )
                out.append(
                    f"| {t['algorithms']} | {t['runs']}{failed} | {_pct(t['coverage'])} | {_pct(t['precision'])} "
                    f"| {_f(t['orientation_error_deg'])} | {corners} "
                    f"| {_f(t['angle_early_deg'])} → {_f(t['angle_late_deg'])} |"
                )
            out.append("")
    d = parts.get("darmstadt")
    if d:
        out += [
            "**The Darmstadt experiment** (seed 000: 3 laps of the 3 m square): end errors against the truth "
            "and the synchronisation's period (ms of sensor time); medians over world seeds.",
            "",
            "| `--algorithms` | runs | dead reckoning mm | filter mm | sync median ms | p99 | within 98-102 ms | within 95-105 ms |",
            "|---|---|---|---|---|---|---|---|",
            f"| seeds (2004) | | {SEED_FIGURES['odometry_mm']} | {SEED_FIGURES['filter_mm']} (early EKF) "
            "| 95-105 | | 85 % | |",
        ]
        for config in dict.fromkeys(run["algorithms"] for run in d["runs"]):
            mine = [run for run in d["runs"] if run["algorithms"] == config]

            def med(key: str, mine: list[dict[str, Any]] = mine) -> float | None:
                return _median([run["sync"][key] for run in mine])

            out.append(
                f"| {config} | {len(mine)} | {_f(_median([run['dead_reckoning_mm'] for run in mine]), 0)} "
                f"| {_f(_median([run['filter_mm'] for run in mine]))} | {_f(med('median_ms'))} "
                f"| {_f(med('p99_ms'))} | {_pct(med('within_98_102'))} | {_pct(med('within_95_105'))} |"
            )
        out.append("")
    files = sorted({p["file"] for p in parts.values() if "file" in p})
    if files:
        out.append("Result files: " + ", ".join(f"[{name}](results/{name})" for name in files) + ".")
    return "\n".join(out).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.seedtable",
        description=__doc__.split("\n\n")[0],
        epilog="examples:\n  python -m bench.seedtable\n  python -m bench.seedtable --parts maps --rooms square --seeds 1-3",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--parts", default=",".join(PARTS), help="comma-separated (default: all)")
    parser.add_argument("--rooms", default="square,office", help="rooms for the maps (default %(default)s)")
    parser.add_argument("--seeds", default="1", help="world seeds for the maps: 1 or 1,2 or 1-3 (default 1)")
    parser.add_argument("--speed", default="10", help="the world's speed-up for the maps (default 10)")
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
    if not args.no_report:
        from bench.report import main as rebuild_report

        return rebuild_report(["--out", str(out_dir)])
    return 0


if __name__ == "__main__":
    sys.exit(main())
