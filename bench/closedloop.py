"""Closed-loop explorations on the command line, scored: the robot without a ring
(:mod:`modules.sim.closedloop`) in several rooms and noise seeds, as a table, JSON or histograms.

``python -m bench.closedloop --world office [--seed 1] [--minutes 30] [--out DIR]`` prints how the
exploration ended and the map's score; ``--world empty,office,square,slanted --seed 1-3 --jobs 2
--variants`` the table for several rooms and noise seeds, each drive's sweeps also mapped by the
seed's method and ours on dead reckoning and on the filtered pose (what ``bench.mapping`` replays
from the ring), ``--json FILE`` keeps it. The ring's own figures come from ``bench.mapping``.
``--generated evaluation --seed 1-3 --plot FILE.png`` runs generated rooms (``bench/rooms.py``:
tuning and evaluation rooms apart) and draws the maps' coverage and precision as histograms.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from modules.sim import closedloop as simulation
from modules.sim.closedloop import VISIT_MS, explore


def format_rows(rows: list[dict[str, Any]]) -> str:
    header = (
        f"{'room':8} {'seed':>4} {'method':7} {'pose':15} {'vectors':>7} {'coverage':>9} "
        f"{'precision':>9} {'orient.':>8} {'corners':>8}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        orient = f"{r['orientation_error_deg']:.1f}°" if r["orientation_error_deg"] is not None else "-"
        lines.append(
            f"{r['room']:8} {r['seed']:4d} {r['method']:7} {r['pose']:15} {r['vectors']:7d} "
            f"{r['coverage']:9.1%} {r['precision']:9.1%} {orient:>8} "
            f"{r['corners_closed']:>4}/{r['corners_total']:<3}"
        )
    return "\n".join(lines)


def contact_summary(results: Iterable[dict[str, Any]]) -> str:
    """One line of the runs' contacts (each a failure): collisions and in how many runs, the
    footprint's closest approach, and the ALERTs and homecomings where the runs counted them;
    empty when no run counted collisions (a drive recorded before they were)."""
    counted = [r for r in results if r.get("collisions") is not None]
    if not counted:
        return ""
    hit = sum(1 for r in counted if r["collisions"])
    parts = [f"{len(counted)} runs: {sum(r['collisions'] for r in counted)} collisions in {hit} runs"]
    closest = [r["closest_mm"] for r in counted if r.get("closest_mm") is not None]
    if closest:
        parts.append(f"closest approach median {np.median(closest):.0f} mm, worst {min(closest):.0f} mm")
    if any("alerts" in r for r in counted):
        parts.append(f"{sum(r.get('alerts', 0) for r in counted)} ALERTs")
    if any("home" in r for r in counted):
        parts.append(f"{sum(bool(r.get('home')) for r in counted)} ended at home")
    return "; ".join(parts)


def summary(rows: list[dict[str, Any]]) -> str:
    """Median and worst decile (10th percentile) of coverage and precision over the runs' maps."""
    if not rows:
        return "no maps"
    coverage = np.array([r["coverage"] for r in rows])
    precision = np.array([r["precision"] for r in rows])
    closed = sum(r["corners_closed"] for r in rows)
    corners = sum(r["corners_total"] for r in rows)
    return (
        f"{len(rows)} maps: coverage median {np.median(coverage):.1%}, worst decile "
        f"{np.percentile(coverage, 10):.1%}, worst {coverage.min():.1%}; precision median "
        f"{np.median(precision):.1%}, worst decile {np.percentile(precision, 10):.1%}, worst "
        f"{precision.min():.1%}; corners closed {closed}/{corners}"
    )


def plot_distribution(rows: list[dict[str, Any]], path: str, title: str) -> None:
    """Histograms of the maps' coverage and precision, their median and worst decile beside
    issue 21's aims (median 90 / 95 %, worst decile 80 / 90 %)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    for ax, name, aim, decile in ((axes[0], "coverage", 90, 80), (axes[1], "precision", 95, 90)):
        values = np.array([r[name] for r in rows]) * 100
        ax.hist(values, bins=np.arange(0, 102.5, 5), color="tab:blue")
        ax.axvline(np.median(values), color="k", label=f"median {np.median(values):.1f} %")
        worst = np.percentile(values, 10)
        ax.axvline(worst, color="k", ls="--", label=f"worst decile {worst:.1f} %")
        ax.axvline(aim, color="tab:green", label=f"aim: median {aim} %, decile {decile} %")
        ax.axvline(decile, color="tab:green", ls="--")
        ax.set_xlabel(f"{name} (%)")
        ax.set_ylabel("maps")
        ax.legend(fontsize=7, loc="upper left")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    Image.open(path).convert("RGB").quantize(64).save(path, optimize=True)  # kilobytes, not 100s


def write_json(
    path: str,
    results: list[dict[str, Any]],
    argv: list[str] | None,
    variants: bool = True,
    timing: dict[str, Any] | None = None,
) -> None:
    """The runs so far, without their move logs (and without the variants' rows unless
    ``variants``: kilobytes), with the command that made them and ``timing`` (seconds, load)."""
    import datetime as dt

    def kept(r: dict[str, Any]) -> dict[str, Any]:
        run = {k: v for k, v in r.items() if k != "log"}
        if not variants and "rows" in run:
            run["rows"] = run["rows"][:1]
        return run

    document = {
        "benchmark": "closedloop",
        "date": dt.datetime.now().isoformat(timespec="seconds"),
        "command": "python -m bench.closedloop " + " ".join(argv if argv is not None else sys.argv[1:]),
        **({"timing": timing} if timing else {}),
        "runs": [kept(r) for r in results],
    }
    Path(path).write_text(json.dumps(document, indent=1) + "\n")


def figures(document: dict[str, Any]) -> dict[str, Any] | None:
    """A result file's runs summed up: collisions, closest approach, ALERTs, coverage and
    precision (median, worst decile), corners, runs ended at home; None for a file from before
    collisions were counted."""
    runs = document.get("runs") or []
    if not runs or any("collisions" not in r for r in runs):
        return None
    rows = [r["rows"][0] if r.get("rows") else r for r in runs]
    coverage = np.array([r["coverage"] for r in rows])
    precision = np.array([r["precision"] for r in rows])
    closest = [r["closest_mm"] for r in runs if r.get("closest_mm") is not None]
    return {
        "runs": len(runs),
        "collisions": sum(r["collisions"] for r in runs),
        "runs_hit": sum(1 for r in runs if r["collisions"]),
        "closest_median_mm": float(np.median(closest)) if closest else None,
        "closest_worst_mm": float(min(closest)) if closest else None,
        # older files counted collisions only: what they did not count is None, not 0
        "alerts": sum(r["alerts"] for r in runs) if all("alerts" in r for r in runs) else None,
        "coverage_median": float(np.median(coverage)),
        "coverage_decile": float(np.percentile(coverage, 10)),
        "precision_median": float(np.median(precision)),
        "precision_decile": float(np.percentile(precision, 10)),
        "corners": (sum(r["corners_closed"] for r in rows), sum(r["corners_total"] for r in rows)),
        "home": sum(1 for r in runs if r["home"]) if all("home" in r for r in runs) else None,
    }


def section_md(documents: list[tuple[str, dict[str, Any]]]) -> str:
    """bench/RESULTS.md's collisions section: one row per closed-loop result file that counts them."""
    lines = []
    for name, document in documents:
        got = figures(document)
        if got is None:
            continue
        timing = document.get("timing") or {}
        load = timing.get("load_start")
        home = "-" if got["home"] is None else f"{got['home']}/{got['runs']}"
        closest = (
            f"{got['closest_median_mm']:.0f} / {got['closest_worst_mm']:.0f}"
            if got["closest_worst_mm"] is not None
            else "-"
        )
        lines.append(
            f"| [{name}](results/{name}) | {document['command'].split('closedloop ', 1)[-1]} | {got['runs']} | "
            f"{got['collisions']} in {got['runs_hit']} | {closest} | "
            f"{'-' if got['alerts'] is None else got['alerts']} | "
            f"{got['coverage_median']:.1%} / {got['coverage_decile']:.1%} | "
            f"{got['precision_median']:.1%} / {got['precision_decile']:.1%} | "
            f"{got['corners'][0]}/{got['corners'][1]} | {home} | "
            + (f"{timing['seconds'] / 60:.0f} min, load {load[0]:.1f}" if load else "-")
            + " |"
        )
    if not lines:
        return ""
    return "\n".join(
        [
            "## Collisions and clearance (closed loop, issue 57)",
            "",
            "Explore 2 in process (`python -m bench.closedloop`), every run's bumper contacts (each a "
            "failure), the footprint's closest approach to any surface (median over runs / worst, mm), "
            "the pilot's ALERT aborts, the maps' coverage and precision (median / worst decile) and "
            "the runs that ended at home. Tuning rooms are 101-130, evaluation rooms 1-30 "
            "(`bench/rooms.py`).",
            "",
            "| file | command | runs | collisions (in runs) | closest mm | ALERTs | coverage | "
            "precision | corners | home | wall time |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
            *lines,
            "",
        ]
    )


def parse_seeds(text: str) -> list[int]:
    """World or noise seeds as the benches take them: ``1``, ``1,2,3``, ``1-3`` or ``1,4-6``."""
    seeds: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        seeds += list(range(int(lo), int(hi or lo) + 1))
    return seeds


def main(argv: list[str] | None = None) -> int:
    from concurrent.futures import ProcessPoolExecutor

    parser = argparse.ArgumentParser(
        prog="python -m bench.closedloop", description=(simulation.__doc__ or "").split("\n\n")[0]
    )
    parser.add_argument("--world", default="office", help="room(s), comma-separated (default office)")
    parser.add_argument(
        "--generated",
        metavar="ROOMS",
        help="generated rooms instead: tuning, evaluation, evaluation:10 or seeds like 101-105 (bench.rooms)",
    )
    parser.add_argument("--seed", default="1", help="noise seed(s): 1 or 1,2,3 or 1-3")
    parser.add_argument("--minutes", type=float, default=30.0, help="simulated minutes at most")
    parser.add_argument(
        "--seed-method", action="store_true", help="the robot runs the seed's vector generation"
    )
    parser.add_argument("--dead-reckoning", action="store_true", help="no Localizer")
    parser.add_argument("--walls", choices=("exploration", "off"), help="the Localizer's walls mode")
    parser.add_argument(
        "--localizer",
        metavar="YAML",
        help="Localizer settings laid over exploration mode's, a file or inline YAML "
        "(e.g. '{walls: {range_model: tangent}}')",
    )
    parser.add_argument("--start-deg", type=float, help="the robot's start heading (default: the room's)")
    parser.add_argument(
        "--visit-ms",
        type=float,
        default=VISIT_MS,
        help=f"how often main and copro see the token, simulated ms (default {VISIT_MS}; the ring at "
        "speed 20 on two cores: 110-140 at the median, bench.mapping prints it)",
    )
    parser.add_argument("--out", metavar="DIR", help="write the maps' PNGs here")
    parser.add_argument("--moves", action="store_true", help="print the navigator's moves")
    parser.add_argument("--variants", action="store_true", help="also score seed/ours × DR/filter")
    parser.add_argument("--jobs", type=int, default=1, help="runs in parallel (default 1)")
    parser.add_argument("--json", metavar="FILE", help="write every run's rows as JSON")
    parser.add_argument("--plot", metavar="PNG", help="the maps' coverage and precision as histograms")
    args = parser.parse_args(argv)
    seeds = parse_seeds(args.seed)
    worlds = [w.strip() for w in args.world.split(",") if w.strip()]
    if args.generated:
        from bench.rooms import generated_room, room_seeds

        rooms_dir = Path(__file__).parent / "results" / "raw" / "rooms"
        worlds = [str(generated_room(n, rooms_dir)) for n in room_seeds(args.generated)]
    jobs = [(w, s) for w in worlds for s in seeds]
    overrides = None
    if args.localizer:
        import yaml

        from tokenring import NumberLoader

        text = Path(args.localizer).read_text() if Path(args.localizer).is_file() else args.localizer
        overrides = yaml.load(text, Loader=NumberLoader) or {}  # bounded: no alias bombs
    options = dict(
        seed_method=args.seed_method,
        dead_reckoning=args.dead_reckoning,
        walls=args.walls,
        minutes=args.minutes,
        start_deg=args.start_deg,
        out=args.out,
        variant_pngs=args.variants,
        overrides=overrides,
        visit_ms=args.visit_ms,
    )
    import os
    import time

    results: list[dict[str, Any]] = []
    began, load_start = time.monotonic(), os.getloadavg()
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futures = [pool.submit(explore, w, s, **options) for w, s in jobs]
        for future in futures:
            result = future.result()
            results.append(result)
            if args.json:  # after each run: a long set interrupted keeps what it measured
                timing = {
                    "seconds": round(time.monotonic() - began, 1),
                    "jobs": args.jobs,
                    "load_start": [round(x, 2) for x in load_start],
                    "load_now": [round(x, 2) for x in os.getloadavg()],
                }
                write_json(args.json, results, argv, args.variants, timing)
            r = result["rows"][0]
            if args.moves:
                print("\n".join(result["log"]))
            print(
                f"{result['room']} seed {result['seed']}: {result['finished']} after "
                f"{result['sim_seconds']:.0f} s simulated; moves {result['moves']}; {r['vectors']} vectors, "
                f"coverage {r['coverage']:.1%}, precision {r['precision']:.1%}, "
                f"orientation {r['orientation_error_deg'] or 0:.1f}°, corners {r['corners_closed']}/{r['corners_total']}; "
                f"collisions {result['collisions']}, closest {result['closest_mm']} mm, "
                f"ALERTs {result['alerts']}, home {'yes' if result['home'] else 'no'}; "
                + ", ".join(
                    f"{k} {v:.4f}" if "scale" in k else f"{k} {v:.1f}"
                    for k, v in result["pose_errors"].items()
                ),
                flush=True,
            )
            for contact in result["contacts"]:
                print(
                    f"  contact at ({contact['x_mm']:.0f}, {contact['y_mm']:.0f}) mm heading "
                    f"{contact['heading_deg']:.0f}°: {contact['bearing_deg']:+.0f}° off the "
                    f"{'tail' if contact['reverse'] else 'nose'} direction"
                )
    rows = [r for result in results for r in (result["rows"] if args.variants else result["rows"][:1])]
    if len(rows) > 1:
        print()
        print(format_rows(rows))
        print(summary([result["rows"][0] for result in results]))
        print(contact_summary(results) or "no runs")
    if args.plot and results:
        rooms = args.generated or args.world
        plot_distribution(
            [result["rows"][0] for result in results],
            args.plot,
            f"Explore 2, closed loop: {len(results)} maps ({rooms}; world seeds {args.seed})",
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
