"""The synchronisation's regularity (issue 20): the seed's 100 ms cycle, old trigger and new, both modes.

Each run is one ``tokenring up --world square --speed K --actions drive.act --localizer cfg.yaml``
(real nodes on real Zenoh, the world simulator, copro hosting the Localizer, main driving an
action file of about 75 s), then ``tokenring analyze --json`` of the Localizer's data log: the
synchronisation period's median, p99 and the shares of cycles within 98-102 ms and 95-105 ms.
The seed (000, §10): "ca. alle 100 ms", between 95 and 105 ms, over 85 % within 98-102 ms.

Triggers (``sync.trigger`` of the Localizer's configuration):

- ``count``: the old default, after one odometry sample at least 100 ms of sensor time after the
  last synchronisation, stamped with that sample's time;
- ``seedcount``: the seed's own, after every odometry sample (count 1, no minimum period);
- ``period``: the new default, at the grid times k·100 ms of the odometry's time, as soon as a
  sample at or past the next one has arrived, stamped with the grid time.

Modes: ``ours`` (every module ours, the default wire of 2.5 Mbit/s; the motor samples its step
counters every loop tick), ``seed`` (``--algorithms seed,copro=ours --profile arcnet``: the seed's
modules at the seed's wire pace; copro stays ours because the seed's copro hosts no Localizer),
``sip`` (ours, the motor sending its counters as the Darmstadt Pioneer's SIPs, every 100 ms of
its clock: ``TOKENRING_MOTOR_SIP_MS=100``) and ``darmstadt`` (``--sensors darmstadt``: the SIPs,
the gyroscope and LOPS). Same-run baseline: every online log is replayed through another trigger
(``tokenring replay --from retrigger``: the period trigger, or the count trigger for a period
run), so the triggers are also compared on exactly the same samples; every online log is also
replayed with its own configuration (``--check``: bit for bit). The load average is printed
beside the figures.

The periods are in sensor time (the stamps the synchronisations carry). ``--arrival`` records each
run (``up --record``) and adds the odometry's arrival: when each new motor.data sample first
travelled on the wire (wall clock, times the speed-up: ms of emulated time). The seed's count
trigger synchronises on each such arrival, so for ``seedcount`` these are its periods in arrival
time, which is what the seed's robot measured (its log's times were the onboard computer's).

    python -m bench.syncregular [--runs 3] [--speed 5] [--modes ours,seed] [--arrival] [--json FILE]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

from tokenring.transport import free_port

#: the drive: three 1.2 m legs with two left turns, about 75 s at 50 %
DRIVE = "# bench.syncregular: three legs of 1.2 m\ne\ns 1200\nr 90\ns 1200\nr 90\ns 1200\n"
TRIGGERS: dict[str, dict[str, Any]] = {
    "count": {"mode": "count", "sensor": "odometry", "count": 1, "min_period_ms": 100},
    "seedcount": {"mode": "count", "sensor": "odometry", "count": 1, "min_period_ms": 0},
    "period": {"mode": "period", "sensor": "odometry", "period_ms": 100},
}
MODES: dict[str, list[str]] = {
    "ours": [],
    "seed": ["--algorithms", "seed,copro=ours", "--profile", "arcnet"],
    "sip": [],
    "darmstadt": ["--sensors", "darmstadt"],
}
#: the motor's SIP setting per mode (modules.description.robot.MOTOR_SIP_ENV; unset: none)
SIP_ENV = "TOKENRING_MOTOR_SIP_MS"
MODE_SIP = {"sip": "100"}
RUN_TIMEOUT_S = 900.0
ATTEMPTS = 2  # a ring that did not come up (a loaded machine) is started once more
FIGURES = ("median_period_ms", "p99_period_ms", "within_98_102ms", "within_95_105ms", "within_2pct")
ARRIVAL = ("arrival_median_ms", "arrival_p99_ms", "arrival_98_102ms", "arrival_95_105ms")


def tokenring(*args: str) -> list[str]:
    return [sys.executable, "-m", "tokenring", *args]


def localizer_config(trigger: str, logs: Path) -> dict[str, Any]:
    """The Localizer's configuration of a run: the defaults, the trigger, the logs' folder."""
    return {"sync": {"trigger": TRIGGERS[trigger]}, "logs": {"directory": str(logs)}}


def analyze(log: Path) -> dict[str, Any]:
    """``tokenring analyze --json`` of a data log: its sync figures and the filter's errors."""
    done = subprocess.run(
        tokenring("analyze", str(log), "--json"), capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        return {"error": done.stderr[-600:]}
    summary = json.loads(done.stdout)
    out: dict[str, Any] = {"syncs": summary["sync"].get("count", 0)}
    out.update({key: summary["sync"].get(key) for key in FIGURES})
    filtered = summary["sources"].get("K", {})
    out["filter_end_error_mm"] = filtered.get("end_error_mm")
    out["filter_rmse_mm"] = filtered.get("rmse_mm")
    return out


def odometry_gaps(log: Path) -> dict[str, Any]:
    """How the step counters reached copro: p99 and largest gap between the new samples it saw
    (sensor time), and how many gaps exceeded 1 s (a stall of the loaded machine: no trigger can
    hold a cycle through it; the period trigger catches up to 1 s and skips grid times beyond)."""
    from modules.localization.logs import read_log

    stamps = [r[0] for r in read_log(log).records if r[1] == "O" and r[2] == "R"]
    gaps = sorted(b - a for a, b in itertools.pairwise(stamps))
    if not gaps:
        return {}
    return {
        "odometry_gap_p99_ms": gaps[min(len(gaps) - 1, int(0.99 * len(gaps)))],
        "odometry_gap_max_ms": gaps[-1],
        "odometry_gaps_over_1s": sum(1 for g in gaps if g > 1000),
    }


def arrivals(recording: Path, speed: float) -> dict[str, Any]:
    """When each new motor.data sample (a new stamp) first travelled on the wire, from a run's
    MCAP recording: the periods between arrivals in ms of emulated time (wall ms x speed-up)."""
    from mcap.reader import make_reader

    times: list[int] = []
    stamps: list[int] = []
    last = None
    with recording.open("rb") as stream:
        for _, _, message in make_reader(stream).iter_messages(topics=["/channel/motor.data"]):
            stamp = json.loads(message.data).get("stamp_ms")
            if stamp != last:
                times.append(message.log_time)
                stamps.append(stamp)
                last = stamp
    periods = sorted((b - a) / 1e6 * speed for a, b in itertools.pairwise(times))
    if not periods:
        return {}
    return {
        "arrivals": len(times),
        "arrival_median_ms": statistics.median(periods),
        "arrival_p99_ms": periods[min(len(periods) - 1, int(0.99 * len(periods)))],
        "arrival_98_102ms": sum(1 for p in periods if 98 <= p <= 102) / len(periods),
        "arrival_95_105ms": sum(1 for p in periods if 95 <= p <= 105) / len(periods),
        # the samples' own stamps as they travelled: with SIPs, a gap over 100 ms is a SIP that
        # never reached the wire (the motor late, or the token away from it for a period)
        "wire_stamps_98_102ms": sum(1 for a, b in itertools.pairwise(stamps) if 98 <= b - a <= 102)
        / len(periods),
    }


def replay(log: Path, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        tokenring("replay", str(log), "--out", str(out), *extra), capture_output=True, text=True, check=False
    )


def drive(
    mode: str, trigger: str, run: int, speed: str, folder: Path, arrival: bool = False
) -> dict[str, Any]:
    """One action-file drive on a fresh ring; the figures of its log and of its replays (and
    with ``arrival`` the odometry's arrival on the wire, from a recording of the run)."""
    name = f"{mode}-{trigger}-{run}"
    logs = folder / name
    logs.mkdir(parents=True)
    config = folder / f"{name}.yaml"
    config.write_text(yaml.safe_dump(localizer_config(trigger, logs)))
    actions = folder / "drive.act"
    actions.write_text(DRIVE)
    ring = f"sync{os.getpid()}x{run}{mode[0]}{trigger[0]}"
    argv = tokenring(
        "up", "--ring", ring, "--listen", f"tcp/127.0.0.1:{free_port()}", "--world", "square",
        "--seed", str(run), "--speed", speed, "--actions", str(actions), "--localizer", str(config),
        "--duration", str(round(600 / float(speed)) + 60), *MODES[mode],
    )  # fmt: skip
    recording = folder / f"{name}.mcap"
    if arrival:
        argv += ["--record", str(recording), "--force"]
    env = {k: v for k, v in os.environ.items() if k != SIP_ENV}
    if mode in MODE_SIP:
        env[SIP_ENV] = MODE_SIP[mode]
    row: dict[str, Any] = {"mode": mode, "trigger": trigger, "run": run}
    for attempt in range(1, ATTEMPTS + 1):
        for old in logs.glob("*"):
            old.unlink()
        row.update(attempt=attempt, load_before=os.getloadavg()[0])
        started = time.monotonic()
        done = subprocess.run(
            argv, capture_output=True, text=True, timeout=RUN_TIMEOUT_S, check=False, env=env
        )
        row.update(seconds=round(time.monotonic() - started, 1), load_after=os.getloadavg()[0])
        data_logs = sorted(logs.glob("*.trlog"))
        if done.returncode == 0 and data_logs:
            row.pop("error", None)
            break
        row["error"] = (done.stdout + done.stderr)[-800:]
    if "error" in row:
        return row
    log = data_logs[-1]
    row["online"] = {**analyze(log), **odometry_gaps(log)}
    if arrival and recording.exists():
        row["online"].update(arrivals(recording, float(speed)))
    checked = replay(log, folder / f"{name}-check.trlog", "--check")
    row["replay_identical"] = checked.returncode == 0
    other = "count" if trigger == "period" else "period"
    other_config = folder / f"{name}-as-{other}.yaml"
    other_config.write_text(yaml.safe_dump(localizer_config(other, logs)))
    retriggered = folder / f"{name}-as-{other}.trlog"
    got = replay(log, retriggered, "--from", "retrigger", "--config", str(other_config))
    row["retriggered"] = (
        {"trigger": other, **analyze(retriggered)}
        if got.returncode == 0
        else {"trigger": other, "error": got.stderr[-600:]}
    )
    return row


def summarize(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One line per mode, trigger and source (online, or the same runs retriggered): medians."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for row in rows:
        if "online" in row and "error" not in row["online"]:
            groups.setdefault((row["mode"], row["trigger"], "online"), []).append(row["online"])
        again = row.get("retriggered", {})
        if again and "error" not in again:
            source = f"replay of {row['trigger']} runs"
            groups.setdefault((row["mode"], again["trigger"], source), []).append(again)
    table = []
    for (mode, trigger, source), figures in sorted(groups.items()):
        line: dict[str, Any] = {"mode": mode, "trigger": trigger, "source": source, "runs": len(figures)}
        keys = (*FIGURES, *ARRIVAL, "syncs", "filter_end_error_mm", "filter_rmse_mm", "odometry_gaps_over_1s")
        for key in keys:
            values = [f[key] for f in figures if f.get(key) is not None]
            line[key] = statistics.median(values) if values else None
        for key in ("within_98_102ms", "arrival_98_102ms"):  # the spread over the runs
            values = [f[key] for f in figures if f.get(key) is not None]
            line[f"{key}_range"] = [min(values), max(values)] if values else None
        loads = [
            r[k]
            for r in rows
            if r["mode"] == mode and r["trigger"] == trigger and source == "online"
            for k in ("load_before", "load_after")
        ]
        line["load"] = [min(loads), max(loads)] if loads else None
        table.append(line)
    return table


def format_table(table: list[dict[str, Any]]) -> str:
    def pct(x: float | None) -> str:
        return "–" if x is None else f"{100 * x:.1f} %"

    def num(x: float | None, fmt: str = ".0f") -> str:
        return "–" if x is None else format(x, fmt)

    def span(x: list[float] | None) -> str:
        return "" if not x or x[0] == x[1] else f" ({100 * x[0]:.0f}-{100 * x[1]:.0f})"

    arrival = any(t.get("arrival_median_ms") is not None for t in table)
    lines = [
        "| mode | trigger | source | runs | median ms | p99 ms | 98-102 ms (runs) | 95-105 ms | ±2 % of median "
        "| syncs | odometry gaps > 1 s | EKF end / RMSE mm | load avg |"
        + (" odometry arrival: median ms | 98-102 ms (runs) | 95-105 ms |" if arrival else ""),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|---|---|" if arrival else ""),
        "| seed (000 §10) | odometry, count 1 | its robot | – | ≈ 100 | ≤ 105 | > 85 % | 100 % | – | – | – | – | – |"
        + (" ≈ 100 | > 85 % | 100 % |" if arrival else ""),
    ]
    for t in table:
        load = "–" if not t["load"] else f"{t['load'][0]:.1f}-{t['load'][1]:.1f}"
        line = (
            f"| {t['mode']} | {t['trigger']} | {t['source']} | {t['runs']} | {num(t['median_period_ms'], '.1f')} "
            f"| {num(t['p99_period_ms'])} | {pct(t['within_98_102ms'])}{span(t.get('within_98_102ms_range'))} "
            f"| {pct(t['within_95_105ms'])} "
            f"| {pct(t['within_2pct'])} | {num(t['syncs'])} | {num(t['odometry_gaps_over_1s'])} "
            f"| {num(t['filter_end_error_mm'], '.1f')} / {num(t['filter_rmse_mm'], '.1f')} | {load} |"
        )  # fmt: skip
        if arrival:
            line += (
                f" {num(t.get('arrival_median_ms'), '.1f')} | {pct(t.get('arrival_98_102ms'))}"
                f"{span(t.get('arrival_98_102ms_range'))} | {pct(t.get('arrival_95_105ms'))} |"
            )
        lines.append(line)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.syncregular",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--runs", type=int, default=3, help="runs per mode and trigger (default %(default)s)")
    parser.add_argument("--speed", default="5", help="the world's speed-up (default %(default)s)")
    parser.add_argument(
        "--modes", default="ours,seed", help="of ours, seed, sip, darmstadt (default %(default)s)"
    )
    parser.add_argument(
        "--triggers", default="count,period", help="of count, seedcount, period (default %(default)s)"
    )
    parser.add_argument(
        "--arrival", action="store_true", help="record each run and add the odometry's arrival periods"
    )
    parser.add_argument("--keep", metavar="DIR", help="keep the logs here (default: a temporary folder)")
    parser.add_argument("--json", metavar="FILE", help="write every run and the table as JSON")
    args = parser.parse_args(argv)
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    triggers = [t.strip() for t in args.triggers.split(",") if t.strip()]
    bad = [m for m in modes if m not in MODES] + [t for t in triggers if t not in TRIGGERS]
    if bad or args.runs < 1:
        print(f"python -m bench.syncregular: unknown mode or trigger {bad} (or --runs < 1)", file=sys.stderr)
        return 2
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="tokenring-syncregular-") as tmp:
        folder = Path(args.keep) if args.keep else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        # runs interleaved (run 1 of every mode and trigger, then run 2, ...): a change of the
        # machine's load falls on all of them alike
        plan = [(m, t, r) for r in range(1, args.runs + 1) for m in modes for t in triggers]
        for i, (mode, trigger, run) in enumerate(plan, 1):
            print(f"  [{i}/{len(plan)}] {mode} {trigger} run {run}", file=sys.stderr, flush=True)
            row = drive(mode, trigger, run, args.speed, folder, args.arrival)
            online = row.get("online", {})
            print(
                f"    {row.get('error', '')[-300:]}"
                if "error" in row
                else f"    median {online.get('median_period_ms')} ms, p99 {online.get('p99_period_ms')} ms, "
                f"98-102 {online.get('within_98_102ms')}, arrival 98-102 {online.get('arrival_98_102ms')}, "
                f"replay identical {row.get('replay_identical')}, "
                f"load {row['load_before']:.1f}->{row['load_after']:.1f}, {row['seconds']} s",
                file=sys.stderr,
                flush=True,
            )
            rows.append(row)
    table = summarize(rows)
    print(f"speed-up {args.speed}, {args.runs} run(s) each, load average (1 min) before/after each run")
    print(format_table(table))
    if args.json:
        Path(args.json).write_text(
            json.dumps({"speed": args.speed, "table": table, "runs": rows}, indent=1) + "\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
