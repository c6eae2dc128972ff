"""The benchmark suite: ``python -m bench [--quick]`` writes bench/results/<date>.json and bench/RESULTS.md.

Each run writes two files: ``bench/results/raw/<date>.json``, everything it recorded including the
per-round round trips and per-command samples (megabytes; the directory is git-ignored), and
``bench/results/<date>.json``, its summary (medians, percentiles, baselines, ratios, counts, the
machine; kilobytes; committed). RESULTS.md's tables come from the summary alone; only the plots
that show samples (the profile's histogram) need the raw file.

Sections (``--sections``; all but the slow ``spurious`` by default):

* ``scaling``    round trip vs ring size at ``--bitrate max``, each ring against a bare Zenoh
                 ring of the same size and topology measured in the same run (ratio, per hop),
                 three topologies: a full mesh of peers, clients of a Zenoh router, and
                 direct links (each hop on a link to the successor, the router for the rest);
                 RSS and USS (private memory) and CPU per node, the launcher's (router's)
                 CPU, a fit of the cost in N;
* ``transports`` the same ring over Zenoh (peers, router), plain UDP sockets and ZeroMQ;
* ``runtime``    Zenoh's async runtime as tokenring sets it (one worker thread for rx and tx)
                 against Zenoh's defaults, both rings (bare and tokenring) under each;
* ``load``       the robot's eight programs running (world simulator, real channel load) vs
                 the same eight nodes idle;
* ``commands``   command latency (send -> acknowledged) in rounds and ms, free inbox and seven
                 senders contending for one inbox, against the seed's n-2 rounds;
* ``profile``    ``--profile arcnet`` on the seed's seven computers vs its 30-40 ms;
* ``recovery``   bench/recovery.py (crash, hang, token loss, partition heal);
* ``download``   bench/download.py (all eight programs through the token).
* ``spurious``   bench/spurious.py: token regenerations with no fault, minutes per configuration
                 (default pace and ``--speed 10``, each with and without a CPU hog on both cores);
                 slow, so only when named: ``--sections spurious [--spurious-minutes M]``.

``--quick`` (under 2 minutes) runs a subset of sizes and sections; sections it leaves out are
taken into RESULTS.md from the latest earlier run that has them, with that run's date. The
robot's own benchmarks (bench/localization.py, bench/mapping.py) take many minutes and are
referenced from their latest result files, never run here.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from bench.ownshare import more_pairs_needed, own_share, pairs_for
from bench.sections import QUICK_SECTIONS, RAW_DIR, SECTIONS, SLOW_SECTIONS, raw_path, summary_of
from tokenring.perf import (
    STEAL_LIMIT_PCT,
    cpu_jiffies,
    describe,
    describe_interleaved,
    steal_pct,
    within_steal_limit,
)
from tokenring.transport import RUNTIME_CHOSEN

HERE = Path(__file__).resolve().parent
RESULTS_DIR = HERE / "results"
#: issue 23's aim for one node process's RSS, printed beside the measured figure
RSS_AIM_MB = 40.0
#: issue 23's aim: the outside tap's median round trip within this many % of the ring's own
TAP_AIM_PCT = 5.0
FULL_SIZES = {"peer": [2, 4, 8, 16, 32, 64], "router": [8, 16, 32, 64, 128, 255], "links": [64, 255]}
QUICK_SIZES = {"peer": [2, 4, 8], "router": [8]}
#: ring sizes at which issue 23 judges tokenring's own share per hop: interleaved there by default
OWN_SHARE_SIZES = (8, 64, 255)
#: pairs of interleaved windows per size: enough for an interval a few microseconds per hop wide
#: at 64 routers, which separate runs do not reach even with many more pairs
INTERLEAVED_PAIRS = 100
INTERLEAVED_PAIRS_QUICK = 6
SEED_NODES = ["main", "motor", "sonar", "compass", "copro", "map", "lcd"]  # the seed's 7 computers


def rounds_for(n: int, quick: bool) -> tuple[int, int]:
    """Rounds measured and discarded for a ring of ``n``: about the same wall time per size."""
    budget = 6000 if quick else 16000
    rounds = int(np.clip(budget / n, 150, 800 if quick else 2000))
    return rounds, max(50, rounds // 5)


def pool_runs(runs: list[Any]) -> Any:
    """One ``RingRun`` from several of the same ring: rounds, CPU and RSS together, the handler
    time of the median run."""
    if len(runs) == 1:
        return runs[0]
    from tokenring.perf import RingRun

    middle = sorted(runs, key=lambda r: r.handler_us.get("median", 0.0))[len(runs) // 2]
    return RingRun(
        [x for r in runs for x in r.rounds_s],
        [x for r in runs for x in r.rss_mb],
        [sum(r.cpu_s[i] for r in runs) for i in range(len(runs[0].cpu_s))],
        middle.handler_us,
        sum(r.wall_s for r in runs),
        middle.stats,
        launcher_cpu_s=sum(r.launcher_cpu_s for r in runs),
        form_s=float(np.median([r.form_s for r in runs])),
        uss_mb=[x for r in runs for x in getattr(r, "uss_mb", [])],
    )


def timeout_for(n: int) -> float:
    return 60.0 + 1.5 * n


class Progress:
    """``[step/total] what ... (elapsed)`` lines on stderr, so a long run shows where it is."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.step = 0
        self.t0 = time.monotonic()

    def say(self, text: str) -> None:
        self.step += 1
        elapsed = time.monotonic() - self.t0
        sys.stderr.write(f"[{self.step}/{self.total} {elapsed:5.0f}s] {text}\n")
        sys.stderr.flush()

    def note(self, text: str) -> None:
        sys.stderr.write(f"{'':>14}{text}\n")
        sys.stderr.flush()


def load_avg() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


def stats_ms(seconds: list[float]) -> dict[str, float]:
    from tokenring.perf import summarize

    return summarize(seconds)


def uss_values(run: Any) -> list[float]:
    """The run's USS figures per node that could be read (none from a record without them)."""
    return [x for x in getattr(run, "uss_mb", []) if not np.isnan(x)]


def memory_line(run: Any) -> str:
    """One node process's memory in a run, beside the aim: ``RSS 38.2 MB (aim <= 40), USS 16.1 MB``."""
    rss = float(np.mean(run.rss_mb))
    text = f"per node: RSS {rss:.1f} MB (aim <= {RSS_AIM_MB:.0f} MB{', met' if rss <= RSS_AIM_MB else ', missed'})"
    uss = uss_values(run)
    return text + (f", USS {np.mean(uss):.1f} MB" if uss else "")


def tap_record(run: Any) -> dict[str, Any]:
    """The outside tap's round trips (a subscriber of the round master's token key, timing the
    frames' arrival) against the master's own figure over the same window."""
    tap = stats_ms(run.tap_rounds_s)
    own = stats_ms(run.rounds_s)
    return {
        "tap_rtt_ms": tap,
        "ring_rtt_ms": own,
        "difference_pct": (tap["median"] / own["median"] - 1) * 100,
        "aim_pct": TAP_AIM_PCT,
    }


def ring_record(run: Any, n: int) -> dict[str, Any]:
    """The figures of one ``run_ring`` result that the report needs."""
    rtt = stats_ms(run.rounds_s)
    uss = uss_values(run)
    return {
        "rtt_ms": rtt,
        "per_hop_us": rtt["median"] * 1e3 / n,
        "handler_us": run.handler_us,
        "send_us": run.stats.get("send_us", {}),
        "rss_mb": {"mean": float(np.mean(run.rss_mb)), "max": float(np.max(run.rss_mb))},
        # USS: the pages only this node holds (RSS counts the interpreter's and Zenoh's shared
        # code in every process); N x USS + one RSS is what a ring of N needs
        "uss_mb": {"mean": float(np.mean(uss)), "max": float(np.max(uss))} if uss else {},
        "rss_aim_mb": RSS_AIM_MB,
        "cpu_per_node_pct": float(np.mean(run.cpu_s) / run.wall_s * 100),
        "cpu_all_nodes_pct": float(np.sum(run.cpu_s) / run.wall_s * 100),
        "launcher_cpu_pct": float(run.launcher_cpu_s / run.wall_s * 100),
        "form_s": run.form_s,
        "rounds_s": [round(x, 7) for x in run.rounds_s],
    }


# ---------------------------------------------------------------------------------------------
# the raw record and its summary


def write_results(results: dict[str, Any], path: Path) -> tuple[Path, Path]:
    """The run's raw record to ``raw/<name>`` beside ``path``, its summary to ``path``; returns both."""
    raw = raw_path(path)
    raw.parent.mkdir(parents=True, exist_ok=True)
    raw.write_text(json.dumps(results, indent=1) + "\n")
    summary = summary_of(results)
    summary["raw"] = f"{RAW_DIR}/{path.name}"  # where the samples are, on the machine that ran it
    path.write_text(json.dumps(summary, indent=1) + "\n")
    return path, raw


# ---------------------------------------------------------------------------------------------
# sections


def section_scaling(ctx: Context) -> dict[str, Any]:
    from tokenring.perf import interleave, run_bare, run_ring

    out: dict[str, Any] = {"runs": []}
    for topology, sizes in ctx.sizes.items():
        for n in sizes:
            rounds, warmup = rounds_for(n, ctx.quick)
            links = topology == "links"
            router = links or topology == "router"
            record: dict[str, Any] = {
                "topology": topology,
                "nodes": n,
                "rounds": rounds,
                "load_before": load_avg(),
            }
            pairs = ctx.pairs_for(n)
            record["pairs"] = pairs
            bare_rounds: list[float] = []
            ring_runs: list[Any] = []
            pair_ratios: list[float] = []
            pair_medians: list[tuple[float, float]] = []  # (ring, bare) ms, for the own share
            pair_steal: list[tuple[float, float]] = []  # (ring, bare) % of the CPUs stolen by the host
            bare_errors: list[str] = []
            ring_errors: list[str] = []
            taken = 0
            while more_pairs_needed(taken, pairs, pair_steal):
                if taken >= pairs:
                    ctx.progress.total += 2  # a retake: the host stole too much of a pair
                taken += 1
                of = f" (pair {taken}/{pairs})" if pairs > 1 else ""
                if taken > pairs:
                    of = f" (retake {taken - pairs}: the host stole over {STEAL_LIMIT_PCT:.0f} % of a pair)"
                ctx.progress.say(f"scaling: bare Zenoh ring, {n} processes, {topology} ({rounds} rounds){of}")
                bare: list[float] = []
                started = cpu_jiffies()
                try:
                    bare = run_bare(n, rounds, warmup, timeout_for(n), router=router, chain=links)
                    bare_rounds += bare
                    ctx.progress.note(f"median {np.median(bare) * 1e3:.3f} ms")
                except Exception as exc:
                    bare_errors.append(str(exc))
                    ctx.progress.note(f"failed: {exc}")
                bare_steal = steal_pct(started, cpu_jiffies())
                ctx.progress.say(f"scaling: tokenring ring, {n} nodes, {topology}{of}")
                tapped = taken == 1  # the outside tap watches the first pair's ring only
                started = cpu_jiffies()
                try:
                    run = run_ring(
                        n, rounds, warmup, timeout=timeout_for(n), router=router, links=links, tap=tapped
                    )
                    ring_runs.append(run)
                    ring_steal = steal_pct(started, cpu_jiffies())
                    ctx.progress.note(
                        f"median {np.median(run.rounds_s) * 1e3:.3f} ms, p99 {np.percentile(run.rounds_s, 99) * 1e3:.3f} ms"
                    )
                    ctx.progress.note(memory_line(run))
                    if tapped and run.tap_rounds_s:
                        record["tap"] = tap_record(run)
                        ctx.progress.note(
                            f"outside tap: median {record['tap']['tap_rtt_ms']['median']:.3f} ms, "
                            f"{record['tap']['difference_pct']:+.1f} % against the ring's own"
                        )
                    if bare:
                        pair_ratios.append(float(np.median(run.rounds_s) / np.median(bare)))
                        pair_medians.append(
                            (float(np.median(run.rounds_s)) * 1e3, float(np.median(bare)) * 1e3)
                        )
                        pair_steal.append((round(ring_steal, 1), round(bare_steal, 1)))
                        ctx.progress.note(f"steal: ring {ring_steal:.1f} %, bare {bare_steal:.1f} %")
                except Exception as exc:
                    ring_errors.append(str(exc))
                    ctx.progress.note(f"failed: {exc}")
            record["pairs_taken"] = taken
            if bare_errors and not bare_rounds:
                record["bare_error"] = bare_errors[-1]
            if ring_errors and not ring_runs:
                record["error"] = ring_errors[-1]
            if (bare_errors and bare_rounds) or (ring_errors and ring_runs):
                record["failed_pairs"] = {"bare": bare_errors, "ring": ring_errors}  # pooled without them
            if bare_rounds:
                record["bare_rtt_ms"] = stats_ms(bare_rounds)
                record["bare_rounds_s"] = [round(x, 7) for x in bare_rounds]
            if ring_runs:
                record.update(ring_record(pool_runs(ring_runs), n))
                if "bare_rtt_ms" in record:
                    record["ratio_median"] = record["rtt_ms"]["median"] / record["bare_rtt_ms"]["median"]
                    record["ratio_p99"] = record["rtt_ms"]["p99"] / record["bare_rtt_ms"]["p99"]
                    record["pair_ratios"] = pair_ratios
                if pair_medians:
                    calm = [
                        m for m, st in zip(pair_medians, pair_steal, strict=True) if within_steal_limit(st)
                    ]
                    record["pair_steal_pct"] = pair_steal
                    record["steal_limit_pct"] = STEAL_LIMIT_PCT
                    record["own_share_us"] = own_share(calm, n)
                    record["own_share_all_us"] = own_share(pair_medians, n)
                    ctx.progress.note(
                        f"tokenring's own share: {describe(record['own_share_us'])} within the steal limit; "
                        f"{describe(record['own_share_all_us'])} over every pair"
                    )
                if pairs > 1:
                    ctx.progress.note(
                        f"pooled: median {record['rtt_ms']['median']:.3f} ms"
                        + (f", ratio {record['ratio_median']:.2f}x" if "ratio_median" in record else "")
                    )
            windows = ctx.windows_for(n)
            if windows:
                ctx.progress.say(
                    f"scaling: both rings of {n} up at once, taking turns ({windows} pairs of windows)"
                )
                try:
                    interleaved = interleave(n, topology, windows, say=ctx.progress.note)
                    interleaved.pop("pids", None)
                    record["interleaved"] = interleaved
                    ctx.progress.note(f"interleaved: {describe_interleaved(interleaved)}")
                except Exception as exc:
                    record["interleaved_error"] = str(exc)
                    ctx.progress.note(f"interleaved windows failed: {exc}")
            record["load_after"] = load_avg()
            out["runs"].append(record)
    out["fits"] = fit_costs(out["runs"])
    return out


def fit_costs(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Least-squares fits of how the cost grows with N, per topology: round trip = a + b N,
    RSS per node (mean), CPU of all nodes together."""
    fits: dict[str, Any] = {}
    for topology in ("peer", "router", "links"):
        good = [r for r in runs if r["topology"] == topology and "rtt_ms" in r]
        if len(good) < 2:
            continue
        n = np.array([r["nodes"] for r in good], float)
        rtt = np.array([r["rtt_ms"]["median"] for r in good])
        b, a = np.polyfit(n, rtt, 1)
        pred = a + b * n
        r2 = 1 - np.sum((rtt - pred) ** 2) / max(np.sum((rtt - rtt.mean()) ** 2), 1e-12)
        # the exponent of a power law rtt ~ N^k, from the log-log slope
        k = float(np.polyfit(np.log(n), np.log(rtt), 1)[0])
        fits[topology] = {
            "rtt_ms_intercept": float(a),
            "rtt_ms_per_node": float(b),
            "r2": float(r2),
            "power_law_exponent": k,
            "rss_mb_per_node": float(np.mean([r["rss_mb"]["mean"] for r in good])),
            "uss_mb_per_node": float(np.mean([r["uss_mb"]["mean"] for r in good if r.get("uss_mb")]))
            if any(r.get("uss_mb") for r in good)
            else float("nan"),
            "sizes": [int(x) for x in n],
        }
    return fits


def section_transports(ctx: Context) -> dict[str, Any]:
    from tokenring.perf import run_bare, run_ring

    sizes = [8] if ctx.quick else [8, 64]
    out: dict[str, Any] = {"runs": []}
    for n in sizes:
        rounds, warmup = rounds_for(n, ctx.quick)
        ctx.progress.say(f"transports: bare Zenoh ring (peers), {n} processes")
        bare = stats_ms(run_bare(n, rounds, warmup, timeout_for(n)))
        ctx.progress.note(f"median {bare['median']:.3f} ms")
        variants = [("zenoh", "peer"), ("zenoh", "router"), ("udp", "-"), ("zmq", "-")]
        for transport, topology in variants:
            ctx.progress.say(
                f"transports: ring of {n} over {transport} {'' if topology == '-' else topology}"
            )
            record: dict[str, Any] = {
                "nodes": n,
                "transport": transport,
                "topology": topology,
                "bare_rtt_ms": bare,
            }
            try:
                run = run_ring(
                    n,
                    rounds,
                    warmup,
                    timeout=timeout_for(n),
                    transport=transport,
                    router=topology == "router",
                )
                record.update(ring_record(run, n))
                record["ratio_to_bare_zenoh"] = record["rtt_ms"]["median"] / bare["median"]
                ctx.progress.note(
                    f"median {record['rtt_ms']['median']:.3f} ms, p99 {record['rtt_ms']['p99']:.3f} ms"
                )
            except Exception as exc:
                record["error"] = str(exc)
                ctx.progress.note(f"failed: {exc}")
            record["load"] = load_avg()
            out["runs"].append(record)
    return out


#: the environments the runtime section runs both rings under: tokenring's (its NODE_RUNTIME, the
#: token's callback on Zenoh's receiving thread), Zenoh's default runtime ("()"), and zenoh-python's
#: default of handing every sample to a Python thread of its own
RUNTIMES: dict[str, dict[str, str]] = {
    "tokenring": {},
    "zenoh defaults": {"ZENOH_RUNTIME": "()"},
    "callback on a Python thread": {"TOKENRING_ZENOH_DIRECT": "0"},
}


def runtime_cases(quick: bool) -> list[tuple[int, str]]:
    return [(8, "peer")] if quick else [(8, "peer"), (8, "router"), (64, "router")]


def bench_cli(args: list[str], timeout: float, env: dict[str, str] | None = None) -> dict[str, Any]:
    """``tokenring bench <args> --json`` in its own process, under tokenring's Zenoh runtimes
    unless ``env`` (which adds to the environment and may override it) sets ``ZENOH_RUNTIME``:
    its results, or ``{"error": why}`` (a failed or overlong run must not end the suite and lose
    its report)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.json"
        cmd = [sys.executable, "-m", "tokenring", "bench", *args, "--quiet", "--json", str(path)]
        environment = {**os.environ, **(env or {})}  # env wins
        if "ZENOH_RUNTIME" in (env or {}):  # the runtime asked for, in the router's process and the nodes'
            environment.pop(RUNTIME_CHOSEN, None)
        elif environment.pop(RUNTIME_CHOSEN, None):  # the benchmark picks tokenring's own, as users get it
            environment.pop("ZENOH_RUNTIME", None)
        try:
            done = subprocess.run(cmd, env=environment, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"error": f"no result in {timeout:.0f} s"}
        if done.returncode != 0 or not path.exists():
            return {"error": (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]}
        return json.loads(path.read_text())


def section_runtime(ctx: Context) -> dict[str, Any]:
    """``tokenring bench`` under each Zenoh runtime, as a subprocess: the runtime is fixed when a
    process first uses Zenoh, and the router lives in the process that runs the benchmark."""
    from tokenring.transport import HOST_RUNTIME, NODE_RUNTIME

    out: dict[str, Any] = {"node_runtime": NODE_RUNTIME, "host_runtime": HOST_RUNTIME, "runs": []}
    for n, topology in runtime_cases(ctx.quick):
        rounds, warmup = rounds_for(n, ctx.quick)
        pairs = pairs_for(n, ctx.quick)
        args = ["--nodes", str(n), "--topology", topology, "--rounds", str(rounds), "--warmup", str(warmup)]
        args += ["--repeat", str(pairs), "--timeout", str(timeout_for(n))]
        for label, env in RUNTIMES.items():
            ctx.progress.say(f"runtime: {n} nodes ({topology}s), bare and tokenring, {label}")
            record: dict[str, Any] = {"nodes": n, "topology": topology, "runtime": label}
            result = bench_cli(args, timeout=4 * timeout_for(n) * pairs, env=env)
            if "error" in result:
                record["error"] = result["error"]
                ctx.progress.note(f"failed: {record['error']}")
            else:
                record.update(
                    rtt_ms=result["rtt_ms"],
                    bare_rtt_ms=result["baseline_rtt_ms"],
                    ratio=result["ratio_median"],
                    per_hop_us=result["per_hop_us"],
                    handler_us=result["handler_us"],
                    cpu_per_node_pct=result["cpu_per_node_pct"]["mean"],
                )
                ctx.progress.note(
                    f"bare {result['baseline_rtt_ms']['median']:.3f} ms, "
                    f"tokenring {result['rtt_ms']['median']:.3f} ms ({result['ratio_median']:.2f}×)"
                )
            record["load"] = load_avg()
            out["runs"].append(record)
    return out


def robot_plans(names: list[str], programs: bool) -> list[Any]:
    from modules.plugin import PROGRAMS_DIR
    from tokenring import default_protocol
    from tokenring.host import NodePlan

    protocol = default_protocol()
    folder = PROGRAMS_DIR
    return [
        NodePlan(protocol.nodes[name].id, name, str(folder / f"{name}.py") if programs else None)
        for name in names
    ]


def world_plan(ring: str, speed: str = "1") -> Any:
    from modules.plugin import world_service

    args = argparse.Namespace(
        world="office", speed=speed, seed=1, ring=ring, log_level="warning", zenoh_config=None
    )
    return world_service(args)


@contextlib.contextmanager
def node_store() -> Iterator[list[str]]:
    """Node arguments keeping program stores in a throw-away directory."""
    with tempfile.TemporaryDirectory(prefix="tokenring-bench-") as store:
        yield ["--store", store]


def section_load(ctx: Context) -> dict[str, Any]:
    from tokenring import default_protocol
    from tokenring.perf import run_ring

    names = [n.name for n in default_protocol().default_nodes]
    rounds, warmup = (1500, 500) if not ctx.quick else (600, 200)
    out: dict[str, Any] = {"nodes": names, "bitrate": "max", "runs": []}
    for label, programs in (("idle", False), ("eight programs", True)):
        ctx.progress.say(f"load: the robot's {len(names)} nodes, {label}, bitrate max")
        ring = f"load{os.getpid()}{int(programs)}"
        with node_store() as store:
            run = run_ring(
                len(names),
                rounds,
                warmup + (1500 if programs else 0),  # programs first calibrate and settle
                timeout=240.0,
                plans=robot_plans(names, programs),
                services=[world_plan(ring)] if programs else [],
                ring=ring,
                extra_node_args=store,
            )
        record = {"label": label, **ring_record(run, len(names)), "load": load_avg()}
        ctx.progress.note(
            f"median {record['rtt_ms']['median']:.3f} ms, handler {record['handler_us']['median']:.0f} us"
        )
        out["runs"].append(record)
    return out


def section_commands(ctx: Context) -> dict[str, Any]:
    from tokenring import default_protocol
    from tokenring.perf import run_ring
    from tokenring.transport import query

    protocol = default_protocol()
    names = [n.name for n in protocol.default_nodes]
    n = len(names)
    count = 10 if ctx.quick else 40
    program = str(HERE / "programs" / "commander.py")
    scenarios = {
        "free inbox (main to each module)": {"main": [f"{x}.command" for x in names if x != "main"]},
        f"{n - 1} senders, one inbox (motor)": {x: ["motor.command"] for x in names if x != "motor"},
    }
    out: dict[str, Any] = {"nodes": n, "bitrate": "max", "seed_worst_rounds": n - 2, "scenarios": []}
    for label, senders in scenarios.items():
        ctx.progress.say(f"commands: {label}, {count} rounds of commands per sender")
        plan = {"send": senders, "count": count, "settle_s": 1.0}
        os.environ["TOKENRING_CMDBENCH"] = json.dumps(plan)
        samples: list[dict[str, Any]] = []
        try:
            collector = CommandCollector(list(senders), query, protocol)
            with node_store() as store:
                plans = robot_plans(names, False)
                for p in plans:
                    p.program = program
                run_ring(
                    n,
                    200,
                    100,
                    timeout=120.0,
                    plans=plans,
                    extra_node_args=store,
                    ring=f"cmd{os.getpid()}{len(out['scenarios'])}",
                    on_ready=collector,
                )
            samples = collector.samples
        finally:
            os.environ.pop("TOKENRING_CMDBENCH", None)
        ok = [s for s in samples if s.get("ms") is not None]
        ms = np.array([s["ms"] for s in ok]) if ok else np.array([np.nan])
        visits = np.array([s["visits"] for s in ok]) if ok else np.array([np.nan])
        waited = np.array([s["waited"] for s in ok]) if ok else np.array([np.nan])
        record = {
            "label": label,
            "senders": senders,
            "commands": len(samples),
            "lost": len(samples) - len(ok),
            "acknowledged": sum(1 for s in ok if s["acked"]),
            "ms": {
                "median": float(np.median(ms)),
                "p99": float(np.percentile(ms, 99)),
                "max": float(np.max(ms)),
            },
            "rounds": {"median": float(np.median(visits)), "max": float(np.max(visits))},
            "waited_rounds": {"median": float(np.median(waited)), "max": float(np.max(waited))},
            "round_ms": collector.round_ms,
            "samples": samples,
        }
        ctx.progress.note(
            f"{len(ok)} commands: median {record['ms']['median']:.2f} ms = {record['rounds']['median']:.0f} rounds; "
            f"waited for the inbox up to {record['waited_rounds']['max']:.0f} rounds"
        )
        out["scenarios"].append(record)
    return out


class CommandCollector:
    """Called by run_ring once the ring circulates: waits for the senders' programs to finish
    and collects their samples (``report()`` of bench/programs/commander.py)."""

    def __init__(self, senders: list[str], query: Callable[..., Any], protocol: Any) -> None:
        self.senders = senders
        self.query = query
        self.protocol = protocol
        self.samples: list[dict[str, Any]] = []
        self.round_ms: dict[str, float] = {}

    def __call__(self, session: Any, ring: str) -> None:
        from tokenring import keys

        deadline = time.monotonic() + 120.0
        pending = set(self.senders)
        while pending and time.monotonic() < deadline:
            for name in sorted(pending):
                node_id = self.protocol.nodes[name].id
                replies = self.query(session, keys.control(ring, node_id, "program"), timeout=2.0)
                if replies and replies[0][1].get("ok"):
                    report = replies[0][1]["result"].get("report", {})
                    if report.get("finished"):
                        self.samples += [dict(s, sender=name) for s in report["samples"]]
                        pending.discard(name)
            time.sleep(0.3)
        main_id = self.protocol.nodes["main"].id
        replies = self.query(session, keys.control(ring, main_id, "stats"), timeout=2.0)
        if replies and replies[0][1].get("ok"):
            self.round_ms = replies[0][1]["result"]["round_ms"]


def section_profile(ctx: Context) -> dict[str, Any]:
    from tokenring import hop_time
    from tokenring.node import PROFILES
    from tokenring.perf import run_ring

    profile = PROFILES["arcnet"]
    n = len(SEED_NODES)
    rounds = 150 if ctx.quick else 600
    out: dict[str, Any] = {
        "profile": profile.name,
        "nodes": SEED_NODES,
        "bitrate": "2.5M",
        "seed_ms": list(profile.reference_ms or ()),
        "model": {
            "wire_ms_per_hop": hop_time(2.5e6) * 1e3,
            "visit_ms": profile.visit_s * 1e3,
            "byte_us": profile.byte_s * 1e6,
            "sonar_lock_ms": [x * 1e3 for x in profile.locks["sonar"]],
        },
        "runs": [],
    }
    for label, programs in (("idle (no programs)", False), ("the seven programs running", True)):
        ctx.progress.say(f"profile arcnet: the seed's {n} computers, {label}")
        ring = f"prof{os.getpid()}{int(programs)}"
        with node_store() as store:
            run = run_ring(
                n,
                rounds,
                60 + (60 if programs else 0),
                bitrate="2.5M",
                profile="arcnet",
                timeout=240.0,
                plans=robot_plans(SEED_NODES, programs),
                services=[world_plan(ring)] if programs else [],
                ring=ring,
                extra_node_args=store,
            )
        record = {"label": label, **ring_record(run, n), "load": load_avg()}
        ctx.progress.note(f"median {record['rtt_ms']['median']:.1f} ms, p90 {record['rtt_ms']['p90']:.1f} ms")
        out["runs"].append(record)
    # what the model alone predicts without any channel copied: wire + visit per hop + the
    # sonar's expected hold (the chance to arrive in the lock times the mean rest of it)
    period, locked = profile.locks["sonar"]
    hold = locked / period * locked / 2
    out["model"]["no_copy_ms"] = n * (hop_time(2.5e6) + profile.visit_s) * 1e3 + hold * 1e3
    out["model"]["sonar_mean_hold_ms"] = hold * 1e3
    return out


def _ms(value: float | None) -> str:
    """A recovery median for the progress line: 0.1 ms is all ten trials can tell."""
    return "none (no trial recovered)" if value is None else f"{value:.1f} ms"


def section_recovery(ctx: Context) -> dict[str, Any]:
    from bench.recovery import run as run_recovery

    trials = 3 if ctx.quick else 10
    ctx.progress.say(f"recovery: crash, hang, loss, heal on an 8-node ring, {trials} trials each")
    kinds = ["crash", "hang", "loss", "heal"]
    report = run_recovery(trials, kinds, "adaptive", quiet=True)
    for kind, s in report["summary"].items():
        ctx.progress.note(f"{kind}: median {_ms(s['median_ms'])}")
    from tokenring.observe import WireTapError, tcpdump_path

    try:
        tcpdump_path()
    except WireTapError as exc:
        ctx.progress.note(f"recovery on direct links not measured: {exc}")
        return report
    ctx.progress.say(f"recovery on direct links (the wire tapped), {trials} trials each")
    links = run_recovery(trials, kinds, "adaptive", quiet=True, topology="links")
    for kind, s in links["summary"].items():
        ctx.progress.note(f"links {kind}: median {_ms(s['median_ms'])}")
    report["links"] = links
    return report


def section_spurious(ctx: Context) -> dict[str, Any]:
    from bench.spurious import pick_configs
    from bench.spurious import run as run_spurious

    minutes = ctx.spurious_minutes or (1.0 if ctx.quick else 5.0)
    return run_spurious(pick_configs(ctx.spurious_configs), minutes, ctx.progress.say, ctx.progress.note)


def section_download(ctx: Context) -> dict[str, Any]:
    from bench.download import run_bitrate

    out: dict[str, Any] = {"runs": []}
    with tempfile.TemporaryDirectory(prefix="tokenring-bench-store-") as store:
        for bitrate in ("2.5M", "max"):
            ctx.progress.say(f"download: all eight programs through the token at {bitrate}")
            result = run_bitrate(bitrate, 1, Path(store))
            ctx.progress.note(
                f"zlib {result['zlib']['seconds_median']:.1f} s, raw {result['raw']['seconds_median']:.1f} s"
            )
            out["runs"].append(result)
    return out


SECTION_FUNCTIONS: dict[str, Callable[[Context], dict[str, Any]]] = {
    "scaling": section_scaling,
    "transports": section_transports,
    "runtime": section_runtime,
    "load": section_load,
    "commands": section_commands,
    "profile": section_profile,
    "recovery": section_recovery,
    "download": section_download,
    "spurious": section_spurious,
}


def pairs_of(n: int, quick: bool, pairs: dict[int, int] | None) -> int:
    """Bare/ring pairs for a ring of ``n``: ``--pairs``' count for ``n``, else its count for
    every size (key 0), else :func:`pairs_for`'s default."""
    chosen = pairs or {}
    return chosen.get(n) or chosen.get(0) or pairs_for(n, quick)


def windows_of(n: int, quick: bool, windows: dict[int, int] | None) -> int:
    """Pairs of interleaved windows (tokenring/perf/interleaved_pairs.py) for a ring of ``n``: ``--interleaved``'s
    count for ``n``, else its count for every size (key 0; 0 turns them off), else
    :data:`INTERLEAVED_PAIRS` (quick: :data:`INTERLEAVED_PAIRS_QUICK`) at the sizes the own
    share's aim names and none elsewhere."""
    chosen = windows or {}
    if n in chosen:
        return chosen[n]
    if 0 in chosen:
        return chosen[0]
    return (INTERLEAVED_PAIRS_QUICK if quick else INTERLEAVED_PAIRS) if n in OWN_SHARE_SIZES else 0


class Context:
    def __init__(
        self,
        quick: bool,
        sizes: dict[str, list[int]],
        progress: Progress,
        spurious_minutes: float | None = None,
        spurious_configs: str | None = None,
        pairs: dict[int, int] | None = None,
        windows: dict[int, int] | None = None,
    ) -> None:
        self.quick = quick
        self.pairs = pairs
        self.windows = windows
        self.sizes = sizes
        self.progress = progress
        self.spurious_minutes = spurious_minutes
        self.spurious_configs = spurious_configs

    def pairs_for(self, n: int) -> int:
        """Alternating bare/ring pairs for a ring of ``n``: ``--pairs`` or :func:`pairs_for`'s."""
        return pairs_of(n, self.quick, self.pairs)

    def windows_for(self, n: int) -> int:
        """Pairs of interleaved windows for a ring of ``n``: ``--interleaved`` or :func:`windows_of`'s."""
        return windows_of(n, self.quick, self.windows)


def count_steps(
    sections: list[str],
    sizes: dict[str, list[int]],
    quick: bool,
    spurious_configs: str | None = None,
    pairs: dict[int, int] | None = None,
    windows: dict[int, int] | None = None,
) -> int:
    from bench.spurious import pick_configs  # a bad --spurious-configs is refused here, before any run

    per = {
        "scaling": sum(
            2 * pairs_of(n, quick, pairs) + (windows_of(n, quick, windows) > 0)
            for v in sizes.values()
            for n in v
        ),
        "transports": 5 * (1 if quick else 2),
        "runtime": len(RUNTIMES) * len(runtime_cases(quick)),
        "load": 2,
        "commands": 2,
        "profile": 2,
        "recovery": 2,
        "download": 2,
        "spurious": len(pick_configs(spurious_configs)) if "spurious" in sections else 0,
    }
    return sum(per[s] for s in sections)


def machine() -> dict[str, Any]:
    from importlib.metadata import version

    from tokenring.node import NATIVE

    mem = Path("/proc/meminfo").read_text().split("\n")[0].split()[1]
    return {
        "cpus": os.cpu_count(),
        "memory_gib": round(int(mem) / 2**20, 1),
        "python": platform.python_version(),
        "zenoh": version("eclipse-zenoh"),
        "pyzmq": version("pyzmq"),
        "kernel": platform.release(),
        "token_path": "C" if NATIVE else "Python",
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="a subset in under 2 minutes")
    parser.add_argument("--sections", help=f"comma-separated subset of {','.join(SECTIONS)}")
    parser.add_argument("--sizes", help="ring sizes for scaling, e.g. peer:2,8,32/router:8,64/links:255")
    parser.add_argument(
        "--pairs",
        help="alternating bare/ring pairs per ring size in scaling, K for every size or N:K,N:K per size "
        "(default 8 up to 64 nodes, 10 beyond): the own share's interval narrows with the square root of the pairs",
    )
    parser.add_argument(
        "--interleaved",
        help="pairs of interleaved windows per ring size in scaling (both rings up at once, taking turns: "
        f"tokenring/perf/interleaved_pairs.py), K or N:K,N:K; 0 for none (default {INTERLEAVED_PAIRS} at 8, 64 and 255 nodes)",
    )
    parser.add_argument("--out", default=str(RESULTS_DIR), help="results directory (default bench/results)")
    parser.add_argument("--no-report", action="store_true", help="write the JSON only, not RESULTS.md")
    parser.add_argument(
        "--spurious-minutes",
        type=float,
        help="minutes per configuration of the spurious section (default 5, --quick 1)",
    )
    parser.add_argument(
        "--spurious-configs",
        help="its configurations, e.g. idle,idle+hog (default: idle, robot, speed10, each also +hog)",
    )
    args = parser.parse_args(argv)
    from tokenring import UsageError
    from tokenring.transport import use_host_runtime

    use_host_runtime()  # as `tokenring up`/`bench` run: the routers in this process, the nodes

    if args.sections:
        sections = [s.strip() for s in args.sections.split(",") if s.strip()]
        unknown = sorted(set(sections) - set(SECTIONS))
        if unknown:
            raise UsageError(f"--sections: unknown {', '.join(unknown)} (known: {', '.join(SECTIONS)})")
    else:
        sections = list(QUICK_SECTIONS) if args.quick else [s for s in SECTIONS if s not in SLOW_SECTIONS]
    sizes = dict(QUICK_SIZES if args.quick else FULL_SIZES)
    if args.sizes:
        sizes = parse_sizes(args.sizes)
    pairs = parse_pairs(args.pairs) if args.pairs is not None else None
    windows = (
        parse_pairs(args.interleaved, "--interleaved", least=0) if args.interleaved is not None else None
    )
    command = "python -m bench" + ("".join(f" {a}" for a in (argv if argv is not None else sys.argv[1:])))
    started = dt.datetime.now()
    results: dict[str, Any] = {
        "date": started.isoformat(timespec="seconds"),
        "command": command.strip(),
        "quick": args.quick,
        "machine": machine(),
        "load_start": load_avg(),
        "sections": {},
        "errors": {},
    }
    progress = Progress(count_steps(sections, sizes, args.quick, args.spurious_configs, pairs, windows))
    sys.stderr.write(f"{command.strip()}: sections {', '.join(sections)}; load {results['load_start']}\n")
    ctx = Context(args.quick, sizes, progress, args.spurious_minutes, args.spurious_configs, pairs, windows)
    for name in sections:
        t0 = time.monotonic()
        try:
            results["sections"][name] = SECTION_FUNCTIONS[name](ctx)
            results["sections"][name]["seconds"] = round(time.monotonic() - t0, 1)
        except Exception as exc:
            results["errors"][name] = f"{type(exc).__name__}: {exc}"
            sys.stderr.write(f"section {name} failed: {exc}\n{traceback.format_exc()}\n")
    results["load_end"] = load_avg()
    results["seconds"] = round(time.monotonic() - progress.t0, 1)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = result_path(out_dir, started, args.quick, sections if args.sections else None)
    _, raw = write_results(results, path)
    sys.stderr.write(f"written {path}, its samples in {raw} ({results['seconds']:.0f} s)\n")
    if not args.no_report:
        from bench.report import write_report

        md = write_report(json.loads(path.read_text()), out_dir, current=path, raw=results)
        sys.stderr.write(f"written {md}\n")
    return 1 if results["errors"] else 0


def result_path(out_dir: Path, started: dt.datetime, quick: bool, sections: list[str] | None) -> Path:
    """``<date>[-quick][-<sections>].json``, with the time added rather than overwrite an earlier
    run's file: a partial run on the same day must not erase the full run's other sections."""
    stem = started.strftime("%Y-%m-%d") + ("-quick" if quick else "")
    if sections:
        stem += "-" + "+".join(sections)
    path = out_dir / f"{stem}.json"
    if path.exists():
        path = out_dir / f"{stem}-{started.strftime('%H%M%S')}.json"
    return path


def parse_sizes(text: str) -> dict[str, list[int]]:
    from tokenring import UsageError

    sizes: dict[str, list[int]] = {}
    for part in text.split("/"):
        topology, _, values = part.partition(":")
        if topology not in ("peer", "router", "links") or not values:
            raise UsageError(f"--sizes {text!r}: expected peer:2,8/router:8,64/links:255")
        try:
            sizes[topology] = [int(v) for v in values.split(",") if v]
        except ValueError:
            raise UsageError(f"--sizes {text!r}: ring sizes are whole numbers") from None
        bad = [v for v in sizes[topology] if not 2 <= v <= 255]
        if bad:
            raise UsageError(f"--sizes: {bad} outside 2..255")
    return sizes


def parse_pairs(text: str, option: str = "--pairs", least: int = 1) -> dict[int, int]:
    """``--pairs`` (or ``option``): ``16`` (every size; key 0) or ``8:16,64:32,255:12`` (per
    ring size), each count ``least`` to 1000."""
    from tokenring import UsageError

    pairs: dict[int, int] = {}
    try:
        for part in text.split(","):
            size, _, count = part.strip().rpartition(":")
            pairs[int(size) if size else 0] = int(count)
    except ValueError:
        raise UsageError(f"{option} {text!r}: expected K or N:K,N:K (whole numbers)") from None
    if any(not least <= k <= 1000 for k in pairs.values()):
        raise UsageError(f"{option} {text!r}: expected {least} to 1000 pairs")
    return pairs


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())
    sys.exit(130)
