"""Mapping quality: the seed's vector generation against ours, on dead reckoning and on the filtered pose.

``python -m bench.mapping [--rooms empty,office,square,slanted] [--speed 20] [--duration 90]``
launches the whole ring once per room (world simulator, Explore 2, ``--bitrate max``) while a
tap records what copro sees at each token visit (``sonar.data``, ``motor.data`` and copro's own
pose and scanning flag). The recording is then replayed through copro's :class:`Vectorizer` four
ways — seed or ours, dead reckoning (``motor.data``) or the filtered pose (copro's ``pose_*``,
from the EKF it hosts) — so all four maps come from the very same drive, and each is scored
against the room's true walls (coverage, precision, orientation error, corners closed). The live
map (ours, as copro ran it) is scored too. PNGs of every map go to ``--out``.

``--generated evaluation --seeds 1,2,3`` explores generated rooms instead (``bench/rooms.py``:
the evaluation rooms are never the ones tuned on) and ends with the live maps' medians and worst
deciles against issue 21's aims.

``--record`` has each ring record itself to ``<out>/<room>.mcap`` (``up --record``: a watcher
costing about a third of a core) and ``--hog N`` runs N busy cores beside each ring: the map
must not depend on how busy the machine is (issue 57). Every run counts its collisions.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from modules.description import keys as robot_keys
from modules.description.robot import STEP_MM

ROOMS = ("empty", "office", "square", "slanted")


class Recorder:
    """Decodes every frame addressed to copro: the data copro's program reads at that visit."""

    def __init__(self, session: Any, ring: str) -> None:
        from tokenring import default_protocol, keys

        protocol = default_protocol()
        self.sonar = protocol.channel("sonar.data")
        self.motor = protocol.channel("motor.data")
        self.copro = protocol.channel("copro.data")
        self.compass = protocol.channel("compass.data")
        self.compass_log: list[dict] = []
        self.last_compass: int | None = None
        self.size = protocol.token_size
        self.records: list[tuple[dict, dict, dict]] = []
        self.last_sweep: int | None = None
        self.motor_log: list[dict] = []
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(keys.token(ring, protocol.node("copro").id), self._on)
        self.truth: list[tuple[int, float, float, float]] = []
        self.collisions = 0  # the world's own count, from its truth stream
        self.closest_mm: float | None = None  # the body's closest approach to a wall so far
        self.truth_sub = session.declare_subscriber(robot_keys.world(ring, "truth"), self._on_truth)

    def _on_truth(self, sample: Any) -> None:
        import msgpack

        msg = msgpack.unpackb(bytes(sample.payload.to_bytes()), raw=False)
        with self.lock:
            self.truth.append((int(msg["stamp_ms"]), float(msg["x"]), float(msg["y"]), float(msg["theta"])))
            self.collisions = int(msg.get("collisions", self.collisions))
            closest = msg.get("closest_mm")
            if closest is not None and math.isfinite(float(closest)):
                self.closest_mm = float(closest)

    def _on(self, sample: Any) -> None:
        frame = sample.payload.to_bytes()
        if len(frame) != self.size + 2:
            return
        token = frame[: self.size]
        sonar = self.sonar.decode(token)
        motor = self.motor.decode(token)
        compass = self.compass.decode(token)
        with self.lock:
            self.motor_log.append(motor)
            if compass["sample"] != self.last_compass and compass["stamp_ms"]:
                self.last_compass = compass["sample"]
                self.compass_log.append(compass)
            if sonar["sweep"] != self.last_sweep and sonar["stamp_ms"]:
                self.last_sweep = sonar["sweep"]
                self.records.append((sonar, motor, self.copro.decode(token)))

    def close(self) -> None:
        self.sub.undeclare()
        self.truth_sub.undeclare()


def replay(
    records: list[tuple[dict, dict, dict]],
    motor_log: list[dict],
    method: int,
    pose_source: str,
    poses: list[tuple[float, float, float]] | None = None,
) -> np.ndarray:
    """The vectors copro's :class:`Vectorizer` makes from a recording (mm); ``poses`` collects
    the pose each sweep was mapped with."""
    from modules.mapping.vectorgen import OUR_METHOD, PoseHistory, Vectorizer, default_layout
    from modules.units import pose_from_wire
    from tokenring import default_protocol

    forward = default_protocol().enums["direction"]["FORWARD"]
    vectors: list[tuple[float, float, float, float]] = []
    vectorizer = Vectorizer(default_layout(), method, vectors.append)
    history = PoseHistory(4096)
    log_index = 0
    for sonar, motor, copro in records:
        while log_index < len(motor_log) and motor_log[log_index]["stamp_ms"] <= motor["stamp_ms"]:
            m = motor_log[log_index]
            history.add(m["stamp_ms"], pose_from_wire(m["x_mm"], m["y_mm"], m["angle_cdeg"]))
            log_index += 1
        dr = pose_from_wire(motor["x_mm"], motor["y_mm"], motor["angle_cdeg"])
        if pose_source == "filter":
            if copro["pose_source"] != 2:
                continue
            pose = pose_from_wire(copro["pose_x_mm"], copro["pose_y_mm"], copro["pose_angle_cdeg"])
            if method == OUR_METHOD:
                pose = history.carry(pose, copro["pose_stamp_ms"], sonar["stamp_ms"])
        else:
            pose = history.at(sonar["stamp_ms"]) if method == OUR_METHOD else dr
        active = bool(copro["scanning"]) and motor["direction"] == forward and motor["distance_mm"] > 10
        vectorizer.sweep(sonar, pose, active)
        if poses is not None and pose is not None:
            poses.append(pose)
    vectorizer.flush()
    return np.asarray(vectors, dtype=float).reshape(-1, 4)


def run_room(
    room: str,
    args: argparse.Namespace,
    out: Path,
    port: int,
    world: str | None = None,
    seed: int | None = None,
) -> dict[str, Any]:
    """One exploration on a fresh ring: ``room`` names its files, ``world`` is the room to load."""
    from tokenring.transport import make_config, open_session

    ring = f"bench{''.join(c for c in room if c.isalnum())}{port}"
    endpoint = f"tcp/127.0.0.1:{port}"
    live = out / f"{room}-live.json"
    world = world or room
    seed = args.seed if seed is None else seed
    cmd = [
        sys.executable, "-m", "tokenring", "--log-level", args.ring_log_level, "up", "--ring", ring, "--listen", endpoint,
        "--world", world, "--speed", str(args.speed), "--seed", str(seed), "--bitrate", args.bitrate,
        "--explore", "2", "--duration", str(args.duration), "--map-out", str(live), "--force",
    ]  # fmt: skip
    if args.programs:
        cmd += ["--programs", args.programs]
    if args.record:
        cmd += ["--record", str(out / f"{room}.mcap")]
    started = time.monotonic()
    finished = ""
    ring_log = (out / f"{room}-ring.log").open("w", encoding="utf-8")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    with open_session(make_config(connect=[endpoint])) as session:
        recorder = None
        while proc.poll() is None:
            if recorder is None:
                time.sleep(1.0)
                recorder = Recorder(session, ring)
            line = proc.stdout.readline() if proc.stdout else ""
            ring_log.write(line)
            if "explore |" in line:
                said = line.split("|", 1)[1].strip()
                print(f"  [{time.monotonic() - started:5.0f} s] {said}", flush=True)
                if said.startswith("exploration "):
                    finished = said.removeprefix("exploration ")
        if recorder is not None:
            recorder.close()
    code = proc.wait()
    ring_log.close()
    return {
        "code": code,
        "records": recorder.records if recorder else [],
        "motor_log": recorder.motor_log if recorder else [],
        "truth": recorder.truth if recorder else [],
        "compass_log": recorder.compass_log if recorder else [],
        "live": live,
        "finished": finished,
        "collisions": recorder.collisions if recorder else None,
        "closest_mm": recorder.closest_mm if recorder else None,
    }


def save_recording(path: Path, result: dict[str, Any]) -> None:
    """The drive as recorded (sweeps and motor samples), for ``--replay``."""
    import msgpack

    keep = ("records", "motor_log", "truth", "compass_log", "collisions", "closest_mm")
    path.write_bytes(msgpack.packb({key: result.get(key) for key in keep}))


def load_recording(path: Path, live: Path) -> dict[str, Any]:
    import msgpack

    from tokenring import UsageError

    if not path.exists():
        raise UsageError(f"{path}: no recorded drive (run without --replay first)")
    data = msgpack.unpackb(path.read_bytes(), raw=False, strict_map_key=False)
    return {
        "code": 0,
        "records": [tuple(r) for r in data["records"]],
        "motor_log": data["motor_log"],
        "truth": data.get("truth", []),
        "compass_log": data.get("compass_log", []),
        "collisions": data.get("collisions"),
        "closest_mm": data.get("closest_mm"),
        "live": live,
        "finished": "(replayed)",
    }


def pose_error(result: dict[str, Any]) -> dict[str, float]:
    """How far copro's filtered pose was from the truth (median, 95th percentile, max; mm and °),
    compared where a truth sample lies within 150 ms of the pose's stamp."""
    import bisect
    import math

    from modules.units import pose_from_wire

    truth = sorted(result.get("truth", []))
    stamps = [t[0] for t in truth]
    position, heading = [], []
    last = None
    for _, _, copro in result["records"]:
        stamp = copro["pose_stamp_ms"]
        if copro["pose_source"] != 2 or stamp == last or not stamps:
            continue
        last = stamp
        i = bisect.bisect_left(stamps, stamp)
        near = min((j for j in (i - 1, i) if 0 <= j < len(stamps)), key=lambda j: abs(stamps[j] - stamp))
        if abs(stamps[near] - stamp) > 150:
            continue
        _, tx, ty, tth = truth[near]
        x, y, th = pose_from_wire(copro["pose_x_mm"], copro["pose_y_mm"], copro["pose_angle_cdeg"])
        position.append(math.hypot(x - tx, y - ty))
        heading.append(abs(math.degrees(math.remainder(th - tth, 2 * math.pi))))
    if not position:
        return {}
    p, h = np.asarray(position), np.asarray(heading)
    return {
        "samples": len(p),
        "position_median_mm": round(float(np.median(p)), 1),
        "position_p95_mm": round(float(np.percentile(p, 95)), 1),
        "position_max_mm": round(float(p.max()), 1),
        "heading_median_deg": round(float(np.median(h)), 2),
        "heading_p95_deg": round(float(np.percentile(h, 95)), 2),
    }


def ring_timing(result: dict[str, Any], step_mm: float = STEP_MM) -> dict[str, Any]:
    """What the closed loop does not model, from the recording: how often copro saw a new
    motor.data sample (the token round, simulated ms), the share of sonar sweeps it never saw (and
    how often a frame brought a sweep older than one seen before), and the world's truth against
    the motor's step counters on straight moves (true over counted travel per move, middle of the
    move only): a stalled motor process leaves the world's robot standing while its counters run
    on, which spreads these ratios beyond the floor's own noise."""
    out: dict[str, Any] = {}
    samples = {m["stamp_ms"]: m for m in result.get("motor_log", []) if m["stamp_ms"]}
    motor = [samples[k] for k in sorted(samples)]
    if len(motor) > 2:
        gaps = np.diff([m["stamp_ms"] for m in motor])
        out["motor_sample_ms"] = {
            "median": float(np.median(gaps)),
            "p90": float(np.percentile(gaps, 90)),
            "max": float(gaps.max()),
        }
    sweeps = [sonar["sweep"] for sonar, _, _ in result.get("records", [])]
    if len(sweeps) > 1:
        out.update(sweep_gaps(sweeps))
    ratios = straight_move_ratios(motor, sorted(result.get("truth", [])), step_mm)
    if ratios:
        r = np.asarray(ratios)
        out["straight_moves"] = {
            "moves": len(r),
            "true_over_counted_median": round(float(np.median(r)), 4),
            "spread_mad": round(float(np.median(np.abs(r - np.median(r)))), 4),
            "off_by_2pct": int(np.sum(np.abs(r - np.median(r)) > 0.02)),
        }
    return out


def sweep_gaps(sweeps: list[int]) -> dict[str, Any]:
    """The share of sonar sweeps never seen in a series of 16-bit sweep counters, and how many
    frames brought a sweep not newer than one seen before (stale)."""
    newest, ahead, stale = sweeps[0], [], 0
    for sweep in sweeps[1:]:
        step = (sweep - newest) & 0xFFFF
        if 0 < step < 0x8000:
            ahead.append(step)
            newest = sweep
        else:
            stale += 1
    span = sum(ahead)
    return {
        "sweeps_missed_fraction": round(1.0 - len(ahead) / span, 4) if span else 0.0,
        "stale_sweeps": stale,
    }


def straight_move_ratios(motor: list[dict], truth: list[tuple], step_mm: float) -> list[float]:
    """Per forward move of at least 1 s (its first and last 300 ms left out): the world's true
    path over the travel its step counters count, fitted over the truth samples inside it."""
    if not motor or len(truth) <= 2:
        return []
    t_true = np.array([t[0] for t in truth], dtype=float)
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(np.array([t[1:3] for t in truth]).T)))])
    ratios = []
    for move in forward_moves(motor):
        start, end = move[0]["stamp_ms"] + 300, move[-1]["stamp_ms"] - 300
        inside = (t_true >= start) & (t_true <= end)
        if end - start >= 1000 and inside.sum() >= 5:
            stamps = np.array([m["stamp_ms"] for m in move], dtype=float)
            counted = np.array([(m["steps_left"] + m["steps_right"]) / 2 for m in move])
            nominal = np.interp(t_true[inside], stamps, counted) * step_mm
            ratios.append(float(np.polyfit(nominal, path[inside], 1)[0]))
    return ratios


def forward_moves(motor: list[dict]) -> list[list[dict]]:
    """motor.data samples in runs of one forward move: consecutive, forward, one ``move_seq``."""
    moves: list[list[dict]] = []
    run: list[dict] = []
    for sample in motor:
        if run and (sample["direction"] != 1 or sample["move_seq"] != run[0]["move_seq"]):
            moves.append(run)
            run = []
        if sample["direction"] == 1:
            run.append(sample)
    if run:
        moves.append(run)
    return moves


def compass_error(result: dict[str, Any], settle_ms: int = 400) -> dict[str, Any]:
    """The compass module's heading against the truth (OK samples only, degrees): steady, and
    within ``settle_ms`` after the motors started or stopped (motor.data's state as recorded)."""
    import bisect
    import math

    from modules.units import cdeg_to_heading

    truth = sorted(result.get("truth", []))
    stamps = [t[0] for t in truth]
    changes, moving = [], None
    for m in result.get("motor_log", []):
        now = m["state"] == 1
        if moving is not None and now != moving:
            changes.append(m["stamp_ms"])
        moving = now
    steady, settling = [], []
    moving: list[tuple[float, float]] = []  # (true heading, signed error) on straight moves
    from tokenring import default_protocol

    direction = default_protocol().enums["direction"]
    straight = (direction["FORWARD"], direction["REVERSE"])
    directions = [(m["stamp_ms"], m["direction"]) for m in result.get("motor_log", []) if m["stamp_ms"]]
    direction_stamps = [d[0] for d in directions]
    states = [c["state"] for c in result.get("compass_log", [])]
    for c in result.get("compass_log", []):
        if c["state"] != 1 or not stamps:
            continue
        i = bisect.bisect_left(stamps, c["stamp_ms"])
        near = min(
            (j for j in (i - 1, i) if 0 <= j < len(stamps)), key=lambda j: abs(stamps[j] - c["stamp_ms"])
        )
        if abs(stamps[near] - c["stamp_ms"]) > 60:
            continue
        north = math.pi / 2  # the bundled rooms' (modules/description/room.py)
        truth_heading = (north - truth[near][3]) % (2 * math.pi)
        signed = math.degrees(math.remainder(cdeg_to_heading(c["heading_cdeg"]) - truth_heading, 2 * math.pi))
        k = bisect.bisect_right(changes, c["stamp_ms"])
        after_change = k > 0 and c["stamp_ms"] - changes[k - 1] < settle_ms
        (settling if after_change else steady).append(abs(signed))
        d = bisect.bisect_right(direction_stamps, c["stamp_ms"]) - 1
        if not after_change and d >= 0 and directions[d][1] in straight:
            moving.append((truth[near][3], signed))
    out: dict[str, Any] = {}
    if states:
        out["disturbed_fraction"] = round(states.count(2) / len(states), 3)
    if len(moving) >= 20:
        # the compass's error on straight moves as a + b cos(heading) + c sin(heading): a running
        # field misjudged by the calibration bends the heading by a first harmonic (b, c)
        theta, err = np.asarray(moving).T
        design = np.column_stack([np.ones_like(theta), np.cos(theta), np.sin(theta)])
        (_, b, c), *_ = np.linalg.lstsq(design, err, rcond=None)
        out["moving_harmonic_deg"] = round(float(math.hypot(b, c)), 2)
    for name, values in (("steady", steady), ("after_start_or_stop", settling)):
        if values:
            v = np.asarray(values)
            out[name] = {
                "samples": len(v),
                "median_deg": round(float(np.median(v)), 2),
                "p95_deg": round(float(np.percentile(v, 95)), 2),
            }
    return out


def main(argv: list[str] | None = None) -> int:
    from bench.closedloop import contact_summary
    from bench.spurious import cpu_hog
    from modules.mapping.vectorgen import OUR_METHOD, SEED_METHOD
    from modules.pc.mapfiles import load_map_file, load_truth, write_map
    from modules.pc.mapscore import score_map
    from tokenring.transport import free_port

    parser = argparse.ArgumentParser(prog="python -m bench.mapping", description=__doc__.split("\n\n")[0])
    parser.add_argument("--rooms", default=",".join(ROOMS), help="comma-separated bundled rooms")
    parser.add_argument("--speed", type=float, default=20.0, help="simulation speed-up (default 20)")
    parser.add_argument("--duration", type=float, default=90.0, help="seconds per room (default 90)")
    parser.add_argument("--bitrate", default="max", help="ring bitrate (default max)")
    parser.add_argument("--seed", type=int, default=1, help="the world's noise seed")
    parser.add_argument("--seeds", help="several noise seeds, e.g. 1,2,3 (each room once per seed)")
    parser.add_argument(
        "--generated",
        metavar="ROOMS",
        help="generated rooms instead of --rooms: evaluation, evaluation:10, tuning or seeds like 1-5 "
        "(bench/rooms.py keeps tuning and evaluation rooms apart)",
    )
    parser.add_argument("--programs", help="module programs directory (default: modules/)")
    parser.add_argument("--out", default="bench-mapping", help="directory for the maps (PNG, JSON)")
    parser.add_argument(
        "--json",
        metavar="FILE",
        help="the results file (default bench/results/mapping-<date>.json; '' for none)",
    )
    parser.add_argument(
        "--ring-log-level",
        default="warning",
        choices=("debug", "info", "warning", "error"),
        help="the ring's log level; its output goes to <out>/<room>-ring.log (info shows main's moves)",
    )
    parser.add_argument(
        "--record", action="store_true", help="each ring records itself to <out>/<room>.mcap (up --record)"
    )
    parser.add_argument(
        "--hog", type=int, default=0, metavar="N", help="N busy cores beside each ring (default 0)"
    )
    parser.add_argument(
        "--replay",
        action="store_true",
        help="no ring: replay the drives recorded in --out by an earlier run (<room>-drive.msgpack)",
    )
    args = parser.parse_args(argv)
    if args.hog < 0:
        parser.error(f"--hog {args.hog}: a number of cores, 0 or more")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    rooms: dict[str, dict[str, Any]] = {}
    worlds = [(r.strip(), r.strip()) for r in args.rooms.split(",") if r.strip()]
    if args.generated:
        from bench.rooms import generated_room, room_seeds

        paths = [generated_room(n, out / "rooms") for n in room_seeds(args.generated)]
        worlds = [(path.stem, str(path)) for path in paths]
    seeds = [int(x) for x in args.seeds.split(",")] if args.seeds else [args.seed]
    runs = [
        (name if len(seeds) == 1 else f"{name}-s{seed}", world_file, seed)
        for name, world_file in worlds
        for seed in seeds
    ]
    for number, (room, world_file, seed) in enumerate(runs, start=1):
        recording = out / f"{room}-drive.msgpack"
        if args.replay:
            result = load_recording(recording, out / f"{room}-live.json")
        else:
            print(
                f"[{number}/{len(runs)}] {room}: exploring for {args.duration:.0f} s at {args.speed:g}x ...",
                flush=True,
            )
            with cpu_hog(args.hog > 0, args.duration + 120.0, max(1, args.hog)):
                result = run_room(room, args, out, free_port(), world_file, seed)
            save_recording(recording, result)
        world, truth = load_truth(world_file)
        print(f"  {len(result['records'])} sweeps recorded, ring exit code {result['code']}", flush=True)
        errors = pose_error(result)
        if errors:
            print(
                f"  filtered pose vs truth: median {errors['position_median_mm']:.0f} mm, "
                f"p95 {errors['position_p95_mm']:.0f} mm, heading median {errors['heading_median_deg']:.1f}°",
                flush=True,
            )
        timing = ring_timing(result)
        if "motor_sample_ms" in timing:
            t = timing["motor_sample_ms"]
            print(
                f"  copro saw a new motor sample every {t['median']:.0f} ms (p90 {t['p90']:.0f}, max {t['max']:.0f}); "
                f"sweeps missed {timing.get('sweeps_missed_fraction', 0.0):.1%}, "
                f"{timing.get('stale_sweeps', 0)} stale (older than one seen before)",
                flush=True,
            )
        if "straight_moves" in timing:
            s = timing["straight_moves"]
            print(
                f"  straight moves, true over counted travel: median {s['true_over_counted_median']:.4f}, "
                f"spread ±{s['spread_mad']:.4f}, {s['off_by_2pct']}/{s['moves']} off by 2 % (the world held by a stall)",
                flush=True,
            )
        compass = compass_error(result)
        if "disturbed_fraction" in compass:
            print(f"  compass DISTURBED in {compass['disturbed_fraction']:.1%} of its readings", flush=True)
        if "moving_harmonic_deg" in compass:
            print(
                f"  compass on straight moves: error ±{compass['moving_harmonic_deg']:.2f}° with the heading",
                flush=True,
            )
        for name in ("steady", "after_start_or_stop"):
            if name not in compass:
                continue
            c = compass[name]
            print(
                f"  compass vs truth, {name.replace('_', ' ')}: median {c['median_deg']:.2f}°, p95 {c['p95_deg']:.2f}° ({c['samples']} samples)",
                flush=True,
            )
        rooms[room] = {
            "ring_exit_code": result["code"],
            "sweeps": len(result["records"]),
            "finished": result.get("finished", ""),
            "collisions": result.get("collisions"),
            "closest_mm": result.get("closest_mm"),
            "pose_error": errors,
            "timing": timing,
            "compass_error": compass,
        }
        variants = [("seed", SEED_METHOD, "dead reckoning"), ("ours", OUR_METHOD, "dead reckoning"),
                    ("seed", SEED_METHOD, "filter"), ("ours", OUR_METHOD, "filter")]  # fmt: skip
        for name, method, source in variants:
            poses: list[tuple[float, float, float]] = []
            vectors = replay(
                result["records"],
                result["motor_log"],
                method,
                "filter" if source == "filter" else "dr",
                poses,
            )
            tag = f"{room}-{name}-{'ekf' if source == 'filter' else 'dr'}"
            paths = {
                "true": np.asarray(result.get("truth", []), dtype=float).reshape(-1, 4)[:, 1:3],
                source: np.asarray(poses, dtype=float).reshape(-1, 3)[:, :2],
            }
            write_map(
                vectors, str(out / f"{tag}.png"), truth, world, title=f"{room}, {name}, {source}", paths=paths
            )
            rows.append({"room": room, "method": name, "pose": source, **score_map(vectors, truth)})
        if result["live"].exists():
            vectors = load_map_file(str(result["live"]))
            rows.append(
                {"room": room, "method": "ours (live)", "pose": "as run", **score_map(vectors, truth)}
            )
    print()
    header = f"{'room':8} {'method':11} {'pose':15} {'vectors':>7} {'coverage':>9} {'precision':>9} {'orient.':>8} {'corners':>8}"
    print(header)
    print("-" * len(header))
    for r in rows:
        orient = f"{r['orientation_error_deg']:.1f}°" if r["orientation_error_deg"] is not None else "-"
        print(
            f"{r['room']:8} {r['method']:11} {r['pose']:15} {r['vectors']:7d} {r['coverage']:9.1%} "
            f"{r['precision']:9.1%} {orient:>8} {r['corners_closed']:>4}/{r['corners_total']:<3}"
        )
    live = [r for r in rows if r["method"] == "ours (live)"]
    if len(live) > 1:
        coverage = np.array([r["coverage"] for r in live])
        precision = np.array([r["precision"] for r in live])
        print(
            f"\n{len(live)} live maps: coverage median {np.median(coverage):.1%}, worst decile "
            f"{np.percentile(coverage, 10):.1%}; precision median {np.median(precision):.1%}, worst decile "
            f"{np.percentile(precision, 10):.1%}; corners closed {sum(r['corners_closed'] for r in live)}/"
            f"{sum(r['corners_total'] for r in live)} (issue 21's aims: 90 / 95 %, worst decile 80 / 90 %)"
        )
    contact = contact_summary(rooms.values())
    if contact:
        print(contact)
    target = args.json if args.json is not None else default_results_path()
    if target:
        Path(target).parent.mkdir(parents=True, exist_ok=True)
        Path(target).write_text(json.dumps(results_document(args, rooms, rows), indent=1) + "\n")
        print(f"\nresults in {target}")
    return 0


def default_results_path() -> str:
    import datetime as dt

    return str(Path(__file__).parent / "results" / f"mapping-{dt.date.today().isoformat()}.json")


def results_document(args: argparse.Namespace, rooms: dict[str, dict[str, Any]], rows: list[dict]) -> dict:
    """The run's settings, what each room's drive did, and the table's rows."""
    import datetime as dt
    import os

    return {
        "benchmark": "mapping",
        "date": dt.datetime.now().isoformat(timespec="seconds"),
        "machine": {"cpus": os.cpu_count(), "load_1min": os.getloadavg()[0]},
        "command": "python -m bench.mapping " + " ".join(sys.argv[1:]),
        "settings": {
            "speed": args.speed,
            "duration_s": args.duration,
            "seed": args.seed,
            "bitrate": args.bitrate,
            "record": args.record,
            "hog_cores": args.hog,
        },
        "aim": "ours with the filter: coverage >= 85 %, precision >= 90 %, corners closed",
        "rooms": rooms,
        "rows": rows,
    }


if __name__ == "__main__":
    sys.exit(main())
