"""The Darmstadt experiment on the ring: 3 laps of a 3 m square, counter-clockwise, by an action file.

``python -m bench.localization [--seeds 1,2,3] [--speed 10] [--laps 3]`` launches the whole ring
with the world simulator (the bundled ``square`` hall, default noise, one noise seed per run),
calibrates the compass (its CALIBRATE turn, over the PC link), hands main the action file
(``s 3000`` / ``r 90`` four times per lap) and waits until it is done. copro hosts the Localizer
(config/localization.yaml: compass + walls of the wall file), whose data log holds dead
reckoning (O), the filter (K) and the ground truth (L, the seed's LOPS role). Printed per seed:
end-point error of dead reckoning and of the filter against the truth, their ratio, the
filter's heading error and RMSE; then the medians. The seed reached > 1500 mm (odometry) and
≈ 300 mm (its early EKF); the aims here: filter ≤ 50 mm and ≤ 1/20 of dead reckoning, heading
within 2°.

``--generated evaluation:N`` drives instead a random action file (``tokenring world drive``,
drive seed = room seed) in each of N generated rooms (``bench.rooms``: tuning and evaluation
rooms apart), the room's walls as the known walls, and reports per run and over all runs the
filter's end error, RMSE, worst error and the share of synchronisations whose truth lay within
the filter's own 3σ (issue 21's aims: median ≤ 20 mm, worst ≤ 50 mm, 3σ ≥ 99 %).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import yaml

from modules.description import keys as robot_keys
from modules.variants import algorithm
from tokenring import NumberLoader
from tokenring.transport import free_port


def square_actions(laps: int, side_mm: int) -> str:
    """The action file of the experiment (seed 000, §10: 3 laps of a 3 m square, counter-clockwise)."""
    lines = [f"# Darmstadt test drive: {laps} laps of a {side_mm / 1000:g} m square, counter-clockwise", "e"]
    for _ in range(laps * 4):
        lines += [f"s {side_mm}", "r 90"]
    return "\n".join(lines) + "\n"


def run_experiment(
    seed: int,
    *,
    speed: float = 10.0,
    laps: int = 3,
    side_mm: int = 3000,
    speed_pct: int = 50,
    workdir: Path,
    timeout: float = 900.0,
    calibrate: bool = True,
    say: Any = print,
    world: str = "square",
    actions: tuple[str, str] | None = None,
    overrides: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """One run on a fresh ring; returns the analysis summary of the Localizer's data log.

    ``world``: the room (its walls are the Localizer's known walls); ``actions``: (name, text) of
    the drive — by default the Darmstadt square, driven after facing +X as in the seed's hall; a
    drive of its own starts where the robot stood before the compass's calibration turn."""
    from modules.pc.analysis import analyse
    from modules.plugin import PROGRAMS_DIR, world_service
    from tokenring import UsageError, load_protocol
    from tokenring.host import Launcher, open_link, plans_from_protocol

    tag = f"{Path(world).stem}-seed{seed}"
    logs = workdir / tag
    logs.mkdir(parents=True, exist_ok=True)
    config = repository_config()
    for key, value in (overrides or {}).items():  # dotted keys, e.g. filter.travel.enabled
        node = config
        *parents, last = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[last] = value
    config["logs"] = {**config.get("logs", {}), "directory": str(logs)}
    if world != "square":
        config["walls"] = {**config.get("walls", {}), "file": world}
    config_path = workdir / f"localization-{tag}.yaml"
    config_path.write_text(yaml.safe_dump(config))
    os.environ["TOKENRING_LOCALIZER_CONFIG"] = str(config_path)
    ring = f"loc{seed}x{os.getpid()}x{time.monotonic_ns() % 1_000_000}"
    world_args = argparse.Namespace(
        world=world, speed=str(speed), seed=seed, log_level="warning", zenoh_config=None, ring=ring
    )
    launcher = Launcher(
        plans_from_protocol(load_protocol(None), None, PROGRAMS_DIR),
        ring=ring,
        bitrate="max",
        log_level="warning",
        services=[world_service(world_args, algorithm("body"))],  # the body seedtable's env chose
        listen=[f"tcp/127.0.0.1:{free_port()}"],  # its own network: two benches at once stay apart
    )
    outcome: dict[str, Any] = {}

    def experiment() -> None:
        try:
            link = open_link(launcher.session, ring, wait=60.0)
            deadline = time.monotonic() + 60.0
            while True:  # main's node answers before its program runs
                try:
                    link.request("state")
                    break
                except UsageError:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.3)
            if calibrate:
                link.command("compass", "CALIBRATE", timeout=10.0)
                wait_for_compass(link, timeout / 4)
                say(f"seed {seed}: compass calibrated")
                time.sleep(2.0)  # the filter takes the calibrated compass in
            if actions is None:
                align(link, speed_pct, timeout / 4)  # face +X, as the robot stood in the seed's hall
            name, text = actions or ("square.act", square_actions(laps, side_mm))
            outcome["drive_start_ms"] = world_now(launcher.session, ring)
            say(f"{tag}: {name} starts at {outcome['drive_start_ms'] / 1000:.1f} s simulated")
            started = time.monotonic()
            state = run_actions(link, text, name, speed_pct, timeout)
            outcome["finished"] = state.get("finished")
            outcome["seconds"] = time.monotonic() - started
            time.sleep(1.0)  # a last synchronisation or two at rest
        except Exception as exc:  # reported, and the ring still stops
            outcome["error"] = f"{type(exc).__name__}: {exc}"
        finally:
            launcher.request_stop()

    launcher.start()
    thread = threading.Thread(target=experiment, daemon=True)
    thread.start()
    launcher.run(timeout + 180.0)
    thread.join(timeout=10)
    if "error" in outcome:
        raise RuntimeError(f"seed {seed}: {outcome['error']}")
    data_logs = sorted(logs.glob("*.trlog"))
    if not data_logs:
        raise RuntimeError(f"seed {seed}: the Localizer wrote no data log into {logs}")
    summary, _ = analyse(data_logs[-1], logs / "plots")
    if outcome.get("drive_start_ms") is not None:
        summary["drive"] = drive_only(data_logs[-1], outcome["drive_start_ms"])
    summary["finished"] = outcome.get("finished")
    summary["drive_seconds"] = outcome.get("seconds")
    return summary


def repository_config() -> dict[str, Any]:
    """config/localization.yaml as a plain dict: the runs use its settings (the sonar model and
    noise it turns on beyond the built-in defaults), with the log directory and walls set per run."""
    from modules.localization.config import default_config_path

    return yaml.safe_load(default_config_path().read_text()) or {}


def run_actions(link: Any, text: str, name: str, speed_pct: int, timeout: float) -> dict[str, Any]:
    """Hand main an action file and wait until its navigator is done."""
    state = link.request("actions", text=text, name=name, speed_pct=speed_pct)
    deadline = time.monotonic() + timeout
    while state.get("running") and time.monotonic() < deadline:
        time.sleep(0.5)
        state = link.request("state")
    return state


def align(link: Any, speed_pct: int, timeout: float) -> None:
    """Turn the robot to face +X by the fused heading (the compass calibration turn left it off).
    The first action file after the calibration squares up to the heading before it (main does
    that, the hall's start faces +X): an empty one; then whatever is left, turned relatively."""
    import math

    from modules.units import cdeg_cw_to_rad_ccw

    run_actions(link, "e\n", "square-up.act", speed_pct, timeout)
    copro = link.read("copro.data")
    heading = math.degrees(cdeg_cw_to_rad_ccw(copro["pose_angle_cdeg"]))
    if round(abs(heading)) >= 1:
        run_actions(link, f"r {-round(heading)}\n", "align.act", speed_pct, timeout)


def world_now(session: Any, ring: str) -> int | None:
    """The simulator's time now (ms), from ``world/state``."""
    from tokenring.transport import query

    for _, reply in query(session, robot_keys.world(ring, "state"), timeout=2.0):
        if reply.get("ok"):
            return int(reply["result"]["stamp_ms"])
    return None


def drive_only(log_path: Path, start_ms: int) -> dict[str, float]:
    """End errors of the action-file drive alone: each source's path re-anchored on the truth at
    the drive's start (a rigid transform), so the compass calibration turn before it does not count —
    the seed's odometry started from a known pose too."""
    import math

    import numpy as np

    from modules.localization.logs import read_log
    from modules.pc.analysis import Series

    series = Series(read_log(log_path))
    truth = series.array("T")
    out: dict[str, float] = {}
    for source in ("O", "K"):
        a = series.array(source)
        after = a[a[:, 0] >= start_ms]
        if not len(after) or not len(truth):
            continue
        t0, x0, y0, p0 = after[0, 0], after[0, 1], after[0, 2], after[0, 3]
        tx0, ty0 = np.interp(t0, truth[:, 0], truth[:, 1]), np.interp(t0, truth[:, 0], truth[:, 2])
        tp = np.unwrap(truth[:, 3])
        rot = float(np.interp(t0, truth[:, 0], tp)) - p0
        c, s = math.cos(rot), math.sin(rot)
        end = after[-1]
        dx, dy = end[1] - x0, end[2] - y0
        ex, ey = tx0 + c * dx - s * dy, ty0 + s * dx + c * dy
        t_end = end[0]
        truth_end = np.interp(t_end, truth[:, 0], truth[:, 1]), np.interp(t_end, truth[:, 0], truth[:, 2])
        heading = math.degrees(
            math.remainder(end[3] + rot - float(np.interp(t_end, truth[:, 0], tp)), 2 * math.pi)
        )
        out[source] = {
            "end_error_mm": float(math.hypot(ex - truth_end[0], ey - truth_end[1])),
            "heading_deg": heading,
        }
    return out


def wait_for_compass(link: Any, timeout: float) -> None:
    """Until compass.data says OK after its CALIBRATE turn."""
    deadline = time.monotonic() + timeout
    seen_calibrating = False
    while time.monotonic() < deadline:
        state = link.read("compass.data")["state"]
        seen_calibrating = seen_calibrating or state == 3
        if state == 1 and seen_calibrating:
            return
        time.sleep(0.5)
    raise TimeoutError("the compass did not finish its calibration")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.localization", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--seeds", default="1,2,3", help="world noise seeds, comma-separated (default 1,2,3)")
    parser.add_argument("--speed", type=float, default=10.0, help="simulation speed-up (default 10)")
    parser.add_argument("--laps", type=int, default=3)
    parser.add_argument("--side-mm", type=int, default=3000)
    parser.add_argument("--speed-pct", type=int, default=50, help="drive speed (100 %% = 10 cm/s)")
    parser.add_argument("--timeout", type=float, default=900.0, help="real seconds per run")
    parser.add_argument(
        "--generated",
        metavar="ROOMS",
        help="instead of the square: a random drive (tokenring world drive) in each generated room, "
        "e.g. evaluation, evaluation:10, tuning, 101-103 (bench.rooms)",
    )
    parser.add_argument("--out", metavar="DIR", help="keep the logs and plots here (default: a temp dir)")
    parser.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override config/localization.yaml"
    )
    args = parser.parse_args(argv)
    args.overrides = {
        k.strip(): yaml.load(v, Loader=NumberLoader) for k, _, v in (item.partition("=") for item in args.set)
    }
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    workdir = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench-localization-"))
    if args.generated:
        return run_generated(args, seeds, workdir)
    rows = []
    for seed in seeds:
        t0 = time.monotonic()
        print(f"seed {seed}: running ({args.laps} laps, speed-up {args.speed:g}) ...", flush=True)
        summary = run_experiment(
            seed,
            speed=args.speed,
            laps=args.laps,
            side_mm=args.side_mm,
            speed_pct=args.speed_pct,
            workdir=workdir,
            timeout=args.timeout,
            overrides=args.overrides,
        )
        k, o = summary["sources"]["K"], summary["sources"]["O"]
        drive = summary.get("drive", {})
        row = {
            "seed": seed,
            "dead_reckoning_drive_mm": drive.get("O", {}).get("end_error_mm"),
            "filter_drive_mm": drive.get("K", {}).get("end_error_mm"),
            "dead_reckoning_mm": o["end_error_mm"],
            "filter_mm": k["end_error_mm"],
            "ratio": k["end_error_mm"] / o["end_error_mm"],
            "filter_heading_deg": k["end_heading_error_deg"],
            "dead_reckoning_heading_deg": o["end_heading_error_deg"],
            "filter_rmse_mm": k["rmse_mm"],
            "filter_max_mm": k["max_error_mm"],
            "within_3sigma": k.get("within_3sigma"),
            "sync_median_ms": summary["sync"].get("median_period_ms"),
            "sync_p99_ms": summary["sync"].get("p99_period_ms"),
            "missed": {s: t["missed"] for s, t in summary["timing"].items()},
            "finished": summary.get("finished"),
            "real_seconds": time.monotonic() - t0,
        }
        rows.append(row)
        print(
            f"seed {seed}: dead reckoning {row['dead_reckoning_mm']:7.0f} mm ({row['dead_reckoning_heading_deg']:+.1f}°)"
            f" | filter {row['filter_mm']:5.1f} mm ({row['filter_heading_deg']:+.2f}°, RMSE {row['filter_rmse_mm']:.1f}, "
            f"worst {row['filter_max_mm']:.1f} mm, within 3σ {row['within_3sigma'] or 0:.1%})"
            f" | ratio 1/{1 / row['ratio']:.0f} | drive alone: dead reckoning {row['dead_reckoning_drive_mm'] or 0:.0f} mm"
            f" | sync {row['sync_median_ms']:.0f}/{row['sync_p99_ms']:.0f} ms"
            f" | {row['real_seconds']:.0f} s | {(row['finished'] or {}).get('why', 'not finished')}",
            flush=True,
        )
    if rows:
        keys = ("dead_reckoning_mm", "filter_mm", "ratio", "dead_reckoning_drive_mm")
        med = {key: statistics.median(r[key] or 0.0 for r in rows) for key in keys}
        worst_heading = max(abs(r["filter_heading_deg"]) for r in rows)
        print(
            f"median over {len(rows)} seeds: dead reckoning {med['dead_reckoning_mm']:.0f} mm, filter "
            f"{med['filter_mm']:.1f} mm (ratio 1/{1 / med['ratio']:.0f}); worst filter heading {worst_heading:.2f}°; "
            f"dead reckoning of the drive alone {med['dead_reckoning_drive_mm']:.0f} mm"
        )
        print(
            "seed 000 (2004): odometry > 1500 mm, early EKF ≈ 300 mm; aims: filter ≤ 50 mm, ≤ 1/20, heading ≤ 2°"
        )
        print(f"logs and plots: {workdir}")
    if args.json:
        Path(args.json).write_text(json.dumps({"runs": rows}, indent=2))
    return 0


def run_generated(args: argparse.Namespace, seeds: list[int], workdir: Path) -> int:
    """Random drives in generated rooms: the filter's end error, RMSE, worst error and how often
    the truth lay within its 3σ, beside dead reckoning; then medians and the worst run."""
    from bench.rooms import generated_room, room_seeds
    from modules.description import load_world
    from modules.description.drives import DriveError, drive_text, generate_drive

    rows: list[dict[str, Any]] = []
    for room_seed in room_seeds(args.generated):
        path = generated_room(room_seed, workdir / "rooms")
        try:
            moves = generate_drive(load_world(path), room_seed)
        except DriveError as exc:  # (room 127: no free leg from where it stands)
            print(f"room {room_seed}: no drive: {exc}", flush=True)
            continue
        text = drive_text(moves, f"random drive {room_seed} in generated room {room_seed}")
        for seed in seeds:
            t0 = time.monotonic()
            print(f"room {room_seed}, seed {seed}: running ...", flush=True)
            try:
                summary = run_experiment(
                    seed,
                    speed=args.speed,
                    speed_pct=args.speed_pct,
                    workdir=workdir,
                    timeout=args.timeout,
                    world=str(path),
                    actions=(f"drive{room_seed}.act", text),
                    overrides=args.overrides,
                )
            except RuntimeError as exc:
                print(f"room {room_seed}, seed {seed}: failed: {exc}", flush=True)
                rows.append({"room": room_seed, "seed": seed, "error": str(exc)})
                continue
            k, o = summary["sources"]["K"], summary["sources"]["O"]
            row: dict[str, Any] = {
                "room": room_seed,
                "seed": seed,
                "filter_mm": k["end_error_mm"],
                "filter_rmse_mm": k["rmse_mm"],
                "filter_max_mm": k["max_error_mm"],
                "within_3sigma": k.get("within_3sigma"),
                "samples_3sigma": k.get("samples_3sigma"),
                "dead_reckoning_mm": o["end_error_mm"],
                "sync_median_ms": summary["sync"].get("median_period_ms"),
                "sync_p99_ms": summary["sync"].get("p99_period_ms"),
                "missed": {s: t["missed"] for s, t in summary["timing"].items()},
                "finished": summary.get("finished"),
                "real_seconds": time.monotonic() - t0,
            }
            rows.append(row)
            print(
                f"room {room_seed}, seed {seed}: filter {row['filter_mm']:.1f} mm (RMSE "
                f"{row['filter_rmse_mm']:.1f}, worst {row['filter_max_mm']:.1f}, within 3σ "
                f"{(row['within_3sigma'] or 0):.1%}) | dead reckoning {row['dead_reckoning_mm']:.0f} mm | "
                f"sync {row['sync_median_ms'] or 0:.0f}/{row['sync_p99_ms'] or 0:.0f} ms, missed "
                f"{sum(row['missed'].values())} | {row['real_seconds']:.0f} s | "
                f"{(row['finished'] or {}).get('why', 'not finished')}",
                flush=True,
            )
    done = [r for r in rows if "error" not in r]
    if done:
        inside = sum((r["within_3sigma"] or 0.0) * (r["samples_3sigma"] or 0) for r in done)
        samples = sum(r["samples_3sigma"] or 0 for r in done)
        print(
            f"{len(done)} drives ({len(rows) - len(done)} failed): filter end error median "
            f"{statistics.median(r['filter_mm'] for r in done):.1f} mm, worst "
            f"{max(r['filter_mm'] for r in done):.1f} mm; RMSE median "
            f"{statistics.median(r['filter_rmse_mm'] for r in done):.1f} mm; within 3σ "
            f"{inside / max(samples, 1):.1%} of {samples} synchronisations; dead reckoning median "
            f"{statistics.median(r['dead_reckoning_mm'] for r in done):.0f} mm"
        )
        print("aims (issue 21): median ≤ 20 mm, worst ≤ 50 mm, within 3σ ≥ 99 %")
    if args.json:
        Path(args.json).write_text(json.dumps({"generated": args.generated, "runs": rows}, indent=2))
    return 0 if len(done) == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
