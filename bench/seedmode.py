"""The 2001 robot beside ours on the ring: maps explored with ``--algorithms seed``, ``ours``,
and each module switched to the seed's alone, scored against the room's true walls.

Each run is one ``tokenring up --world W --explore 2 --algorithms A --map-out m.json`` (real
nodes, real Zenoh, the world simulator), then ``tokenring score``; rows are medians over rooms
and world seeds. The seed's documented flaws show as missing corners and an orientation error
that grows along the drive (the late third of the map's vectors against the early third).

    python -m bench.seedmode [--world office,square] [--seed 1-3] [--speed 10] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench.closedloop import parse_seeds
from bench.seedreport import maps_table
from modules.variants import PARTS
from tokenring.transport import free_port

#: every configuration a table row is about: the two robots, then each module seed alone
CONFIGS = ("ours", "seed", *(f"{part}=seed" for part in PARTS))
RUN_TIMEOUT_S = 1800.0


def tokenring(*args: str) -> list[str]:
    return [sys.executable, "-m", "tokenring", *args]


def explore(
    world: str, seed: int, algorithms: str, speed: str, minutes: float, folder: Path, bitrate: str = "max"
) -> dict[str, Any]:
    """One exploration on a fresh ring; its map's score, or the failure's last lines.

    ``bitrate`` max by default: the ring's round trip (median 2.5 ms, p99 10 ms exploring the
    office) times the speed-up is then about the seed's 30-40 ms of robot time at speed 10. At the seed's
    pace (``--profile arcnet``, 31 ms) only speed 1 keeps that: at speed 10 the pilot would hear
    of a wall 300 ms of robot time late and the seed's robot, which stops at 12 cm, drives into
    ALERT."""
    name = f"{world}-{seed}-{algorithms.replace('=', '-')}"
    out = folder / f"{name}.json"
    ring = f"seed{os.getpid()}{abs(hash(name)) % 10**6}"
    argv = tokenring(
        "up", "--ring", ring, "--listen", f"tcp/127.0.0.1:{free_port()}", "--world", world, "--seed", str(seed),
        "--speed", speed, "--explore", "2", "--algorithms", algorithms, "--map-out", str(out),
        "--duration", str(round(minutes * 60 / float(speed))), "--bitrate", bitrate,
    )  # fmt: skip
    done = subprocess.run(argv, capture_output=True, text=True, timeout=RUN_TIMEOUT_S, check=False)
    row: dict[str, Any] = {"world": world, "seed": seed, "algorithms": algorithms, "exit": done.returncode}
    if not out.exists():
        row["error"] = (done.stdout + done.stderr)[-600:]
        return row
    scored = subprocess.run(
        tokenring("score", str(out), "--world", world, "--json"), capture_output=True, text=True, check=False
    )
    if scored.returncode != 0:
        row["error"] = scored.stderr[-600:]
        return row
    row.update(json.loads(scored.stdout))
    row["map"] = out.name  # the file's own name: its scratch directory is gone after the run
    row.update(drift(out, world))
    end = json.loads(out.read_text()).get("end_pose") or {}  # main's pose against the truth
    row["end_error_mm"] = end.get("error_mm")
    return row


def drift(map_file: Path, world: str) -> dict[str, Any]:
    """Orientation error (°, length-weighted) of the map's early and late thirds of vectors, in
    the order they were recorded: the seed's dead-reckoned heading error grows along the drive."""
    from modules.pc.mapfiles import load_map_file, load_truth
    from modules.pc.mapscore import angle_diff, directions, point_segment_distance

    vectors = np.asarray(load_map_file(str(map_file)), dtype=float).reshape(-1, 4)
    walls = np.asarray(load_truth(world)[1], dtype=float).reshape(-1, 4)
    if len(vectors) < 3 or not len(walls):
        return {}
    middles = (vectors[:, :2] + vectors[:, 2:]) / 2
    nearest = walls[point_segment_distance(middles, walls).argmin(axis=1)]  # each vector's wall
    err = np.degrees(angle_diff(directions(vectors), directions(nearest)))
    lengths = np.hypot(vectors[:, 2] - vectors[:, 0], vectors[:, 3] - vectors[:, 1])
    third = len(vectors) // 3
    early, late = slice(0, third), slice(len(vectors) - third, len(vectors))
    return {
        "angle_early_deg": float((err[early] * lengths[early]).sum() / lengths[early].sum()),
        "angle_late_deg": float((err[late] * lengths[late]).sum() / lengths[late].sum()),
    }


def summarize(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    table = []
    for config in dict.fromkeys(r["algorithms"] for r in rows):
        mine = [r for r in rows if r["algorithms"] == config and "coverage" in r]

        def median(key: str, runs: list[dict[str, Any]] = mine) -> float | None:
            values = [r[key] for r in runs if r.get(key) is not None]
            return float(np.median(values)) if values else None

        table.append(
            {
                "algorithms": config,
                "runs": len(mine),
                "failed": sum(1 for r in rows if r["algorithms"] == config and "coverage" not in r),
                "coverage": median("coverage"),
                "precision": median("precision"),
                "orientation_error_deg": median("orientation_error_deg"),
                "corners_closed": median("corners_closed"),
                "corners_total": median("corners_total"),
                "angle_early_deg": median("angle_early_deg"),
                "angle_late_deg": median("angle_late_deg"),
                "end_error_mm": median("end_error_mm"),
            }
        )
    return table


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.seedmode",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--world", default="office,square", help="rooms, comma-separated (default %(default)s)"
    )
    parser.add_argument("--seed", default="1-3", help="world seeds: 1 or 1,2 or 1-3 (default %(default)s)")
    parser.add_argument("--speed", default="10", help="the world's speed-up (default %(default)s)")
    parser.add_argument("--bitrate", default="max", help="the ring's bitrate (default %(default)s)")
    parser.add_argument("--minutes", type=float, default=40.0, help="emulated minutes per run at most")
    parser.add_argument(
        "--configs",
        default="|".join(CONFIGS),
        help="--algorithms values, '|'-separated (default %(default)s)",
    )
    parser.add_argument("--json", metavar="FILE", help="write every run and the table as JSON")
    args = parser.parse_args(argv)
    configs = [c.strip() for c in args.configs.split("|") if c.strip()]
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="tokenring-seedmode-") as tmp:
        runs = [(w, s, c) for w in args.world.split(",") for s in parse_seeds(args.seed) for c in configs]
        for i, (world, seed, config) in enumerate(runs, 1):
            print(
                f"  [{i}/{len(runs)}] {world} seed {seed} --algorithms {config}", file=sys.stderr, flush=True
            )
            rows.append(explore(world, seed, config, args.speed, args.minutes, Path(tmp), args.bitrate))
    table = summarize(rows)
    print(maps_table(table))
    if args.json:
        Path(args.json).write_text(json.dumps({"table": table, "runs": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
