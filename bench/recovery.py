"""Recovery benchmark: how fast an 8-node ring at ``--bitrate max`` comes back from faults.

    python -m bench.recovery [--trials 10] [--topology peers|links] [--json FILE]

For each trial a fault is injected at run time and the wire is watched: the recovery time is
from the injection until the token has gone one full round through every node that should be
in the ring (one chain, one epoch). Faults: ``crash`` (the node's process exits; the launcher
respawns it between trials), ``hang`` (SIGSTOP; the successor must be skipped by the pass
acknowledgement, long before Zenoh's 10 s lease), ``loss`` (a token swallowed after its pass
was acknowledged: only the reconfiguration timeout finds it) and ``heal`` (a partition into two
rings of four is healed; time until one token goes round all eight). Aims (issue 3): crash
median < 50 ms, hang < 150 ms, loss < 100 ms.

``--topology links`` runs the same trials with the launcher as the nodes' router and the hop on
direct links (issue 23): no subscriber sees those frames, so the wire is captured (tcpdump on
every link port, and frames out of the router for passes past a dead successor) and judged the
same way.
"""

from __future__ import annotations

import argparse
import datetime as dt
import io
import json
import os
import random
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from tokenring import keys
from tokenring.chaos import WireCapture, recovery_time
from tokenring.host import FaultClient, Launcher, NodePlan
from tokenring.observe import WireTap, first_full_round, passes, settled
from tokenring.transport import free_port, make_config, open_session, query

IDS = [10, 20, 30, 40, 50, 60, 70, 80]
AIMS_MS = {"crash": 50.0, "hang": 150.0, "loss": 100.0}


def counters(session: Any, ring: str) -> dict[tuple[int, int], tuple[int, int]]:
    """Per node process (ID, pid): (tokens regenerated, duplicates eliminated)."""
    out = {}
    for _, reply in query(session, keys.control(ring, "*", "stats"), timeout=1.0):
        if reply.get("ok"):
            result = reply["result"]
            stats = result["stats"]
            out[(result["id"], result["pid"])] = (
                stats["tokens_regenerated"],
                stats["stale_tokens"] + stats["duplicate_passes"],
            )
    return out


def delta(before: dict, after: dict) -> tuple[int, int]:
    """Growth per node process; a respawned node starts from zero."""
    regen = dup = 0
    for key, (r, d) in after.items():
        r0, d0 = before.get(key, (0, 0))
        regen += r - r0
        dup += d - d0
    return regen, dup


def wait_whole(capture: WireCapture | WireTap, members: list[int], timeout: float = 20.0) -> bool:
    """Until the last 0.5 s of the wire show exactly one token round ``members``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        now = time.perf_counter()
        seq, _ = passes([f for f in capture.snapshot() if f[0] >= now - 0.5])
        if settled(seq) and first_full_round(seq[len(seq) // 2 :], members) is not None:
            return True
        time.sleep(0.1)
    return False


def trial(
    kind: str,
    client: FaultClient,
    capture: WireCapture | WireTap,
    session: Any,
    ring: str,
    rng: random.Random,
) -> dict[str, Any]:
    victim = rng.choice(IDS[1:-1])  # a middle node: neither main (round master) nor the highest
    before = counters(session, ring)
    if kind == "heal":
        client_groups = [IDS[:4], IDS[4:]]
        for node_id in IDS:
            client.inject(node_id, {"kind": "partition", "groups": client_groups})
        time.sleep(1.0)
        start = time.perf_counter()
        for node_id in IDS:
            client.inject(node_id, {"kind": "heal"})
        expected = IDS
    else:
        request = {
            "crash": {"kind": "crash"},
            "hang": {"kind": "hang", "soft": False},
            "loss": {"kind": "lose", "count": 1},
        }[kind]
        start = time.perf_counter()
        answer = client.inject(victim, request)
        # a crash or hang takes effect a moment after its answer left (tokenring.node.faults): the
        # recovery counts from then, not from the request
        start = max(start, time.perf_counter() + float(answer.get("effective_in_s", 0.0)))
        expected = IDS if kind == "loss" else [i for i in IDS if i != victim]
    deadline = time.monotonic() + 10
    took = None
    while time.monotonic() < deadline and took is None:
        time.sleep(0.2)
        took = recovery_time(capture.snapshot(), [set(expected)], start, time.perf_counter())
    after = counters(session, ring)
    diagnosis = None
    if took is None:  # what the wire shows instead, for the report
        now = time.perf_counter()
        seq, _ = passes([f for f in capture.snapshot() if f[0] >= now - 0.5])
        diagnosis = {
            "receivers_last_500ms": sorted({p.did for p in seq}),
            "epochs": sorted({(p.epoch, p.origin) for p in seq}),
            "passes": len(seq),
        }
    if kind == "hang":
        client.resume(victim)
    ok = wait_whole(capture, IDS)
    return {
        "kind": kind,
        "victim": victim if kind != "heal" else None,
        "recovered_ms": None if took is None else took * 1e3,
        "tokens_regenerated": delta(before, after)[0],
        "duplicates_eliminated": delta(before, after)[1],
        "whole_again": ok,
        "diagnosis": diagnosis,
    }


def run(
    trials: int, kinds: list[str], ack: str, quiet: bool = False, topology: str = "peers"
) -> dict[str, Any]:
    """``trials`` of each fault in ``kinds``; ``topology`` ``peers`` (a full mesh: a subscriber
    of every token key sees each frame) or ``links`` (the launcher the nodes' router, the hop on
    direct links no subscriber sees: the wire is captured instead, :mod:`tokenring.observe.pcap_tap`)."""
    links = topology == "links"
    port = free_port()
    ring = f"rec{port}"
    endpoint = f"tcp/127.0.0.1:{port}"
    launcher = Launcher(
        [NodePlan(i, "") for i in IDS],
        ring=ring,
        bitrate="max",
        ack_mode=ack,
        listen=[endpoint],
        log_level="warning",
        respawn=True,
        output=io.StringIO(),
        router=links,
        links=links,
    )
    for plan in launcher.plans:
        plan.name = {
            10: "main",
            20: "motor",
            30: "sonar",
            40: "compass",
            50: "copro",
            60: "map",
            70: "lcd",
            80: "charger",
        }[plan.node_id]
    rng = random.Random(7)
    results: list[dict[str, Any]] = []
    wire_tap: WireTap | None = None
    launcher.start()
    try:
        with open_session(make_config(mode="client" if links else "peer", connect=[endpoint])) as session:
            capture: WireCapture | WireTap
            if links:  # every node's link port either way, and frames out of the router
                capture = wire_tap = WireTap.around(launcher.link_ports.values(), port)
                wire_tap.start()
            else:
                capture = WireCapture(session, ring)
            if not wait_whole(capture, IDS, timeout=60):
                raise SystemExit("the ring did not form")
            time.sleep(2.0)  # let every node's timeouts follow its measurements
            client = FaultClient(session, ring, timeout=3.0)
            total = trials * len(kinds)
            for index in range(total):
                kind = kinds[index % len(kinds)]
                result = trial(kind, client, capture, session, ring, rng)
                results.append(result)
                if not quiet:
                    took = (
                        "not recovered"
                        if result["recovered_ms"] is None
                        else f"{result['recovered_ms']:.1f} ms"
                    )
                    extra = f" {result['diagnosis']}" if result["diagnosis"] else ""
                    sys.stderr.write(
                        f"[{index + 1}/{total}] {kind:5s} node {result['victim']}: {took}{extra}\n"
                    )
                capture.clear()
                time.sleep(0.3)
            capture.close()
    finally:
        if wire_tap is not None:
            wire_tap.stop()  # (again: a run that failed leaves no capture behind)
        launcher.stop()
    summary = {}
    for kind in kinds:
        times = [r["recovered_ms"] for r in results if r["kind"] == kind and r["recovered_ms"] is not None]
        failed = sum(1 for r in results if r["kind"] == kind and r["recovered_ms"] is None)
        summary[kind] = {
            "trials": sum(1 for r in results if r["kind"] == kind),
            "not_recovered": failed,
            "median_ms": float(np.median(times)) if times else None,
            "p90_ms": float(np.percentile(times, 90)) if times else None,
            "max_ms": float(max(times)) if times else None,
            "aim_ms": AIMS_MS.get(kind),
            "tokens_regenerated": sum(r["tokens_regenerated"] for r in results if r["kind"] == kind),
            "duplicates_eliminated": sum(r["duplicates_eliminated"] for r in results if r["kind"] == kind),
        }
    return {
        "benchmark": "recovery",
        "topology": topology,
        "nodes": len(IDS),
        "bitrate": "max",
        "ack": ack,
        "date": dt.datetime.now().isoformat(timespec="seconds"),
        "machine": {"cpus": os.cpu_count(), "load_1min": os.getloadavg()[0]},
        "summary": summary,
        "trials": results,
    }


def format_summary(report: dict[str, Any]) -> str:
    from tokenring.cli import format_table

    rows = []
    for kind, s in report["summary"].items():

        def ms(v: float | None) -> str:
            return "-" if v is None else f"{v:.1f}"

        verdict = (
            ""
            if s["aim_ms"] is None or s["median_ms"] is None
            else ("ok" if s["median_ms"] < s["aim_ms"] else "MISSED")
        )
        rows.append(
            [
                kind,
                s["trials"],
                ms(s["median_ms"]),
                ms(s["p90_ms"]),
                ms(s["max_ms"]),
                "-" if s["aim_ms"] is None else f"< {s['aim_ms']:.0f}",
                verdict,
                s["not_recovered"],
                s["tokens_regenerated"],
                s["duplicates_eliminated"],
            ]
        )
    where = " on direct links (the wire tapped)" if report.get("topology") == "links" else ""
    head = f"recovery, {report['nodes']} nodes{where}, bitrate {report['bitrate']}, ack {report['ack']} (load {report['machine']['load_1min']:.1f})"
    return (
        head
        + "\n"
        + format_table(
            rows,
            ["fault", "trials", "median ms", "p90 ms", "max ms", "aim", "", "failed", "regen", "dup elim"],
        )
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.recovery",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--trials", type=int, default=10, help="trials per fault (default %(default)s)")
    parser.add_argument("--faults", default="crash,hang,loss,heal", help="which faults (default %(default)s)")
    parser.add_argument("--ack", default="adaptive", choices=("adaptive", "always", "never"))
    parser.add_argument(
        "--topology",
        default="peers",
        choices=("peers", "links"),
        help="a full mesh of peers, or the launcher as router with the hop on direct links "
        "(timed from the wire with tcpdump; default %(default)s)",
    )
    parser.add_argument("--json", metavar="FILE", help="write the report as JSON")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    kinds = [k.strip() for k in args.faults.split(",") if k.strip()]
    unknown = set(kinds) - {"crash", "hang", "loss", "heal"}
    if unknown:
        parser.error(f"unknown fault(s) {', '.join(sorted(unknown))} (crash, hang, loss, heal)")
    from tokenring.transport import use_host_runtime

    use_host_runtime()  # as the suite and `tokenring up` run: the launcher's router in this process
    if args.topology == "links":
        from tokenring.observe import WireTapError, tcpdump_path

        try:
            tcpdump_path()
        except WireTapError as exc:
            parser.error(str(exc))
    report = run(args.trials, kinds, args.ack, args.quiet, args.topology)
    print(format_summary(report))
    name = "recovery" if args.topology == "peers" else f"recovery-{args.topology}"
    out = (
        Path(args.json)
        if args.json
        else Path(__file__).parent / "results" / f"{name}-{report['date'][:10]}.json"
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
