"""Where a hop's CPU goes: a tokenring node against a bare Zenoh forwarder, thread by thread.

Alternating pairs of one bare Zenoh ring (``tokenring.perf.bare_ring``) and one tokenring ring of
the same size and topology; in each, once the token circulates, a window of ``--window`` seconds:

* every node's threads' CPU time (``/proc/PID/task/TID/stat``) before and after, grouped by what
  the thread does — the token's receiving thread (Zenoh's ``rx-*``, where the visit runs), Zenoh's
  sending and timer threads (``tx-*``, ``net-*``, ``acc-*``, ``app-*``), the Python threads (the
  node's watchdog, token and system threads; the bare forwarder has only its idle main thread) —
  and their context switches, each divided by the visits in the window;
* with ``--perf``, ``perf record`` of one node (the second; ``--perf-nodes K``: the K after the
  first, for enough samples in a big ring's slow rounds) over the window, its samples split by
  thread and library (``_tokenpath`` is the visit in C, ``libpython`` the Python it calls,
  ``zenoh`` the transport, the kernel the syscalls and wake-ups), in µs per visit.

The visits in the window are counted, not estimated: the ring's master answers ``visits``, the bare
ring's process 0 prints each round's arrival time. Each row's ring - bare difference is given as
the mean over pairs with its 95 % interval (tokenring/perf/hop_overhead.py).

    python -m bench.hopcost --nodes 8 --pairs 3 --window 5 --perf [--json F]
    python -m bench.hopcost --nodes 64 --topology router --pairs 2 --perf
    python -m bench.hopcost --nodes 255 --topology router --pairs 1 --perf --perf-nodes 32
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tokenring.perf import BareRing, LiveRing, interval

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
PERF_HZ = 1999
THREAD_GROUPS = (
    ("token receive (Zenoh rx, the visit)", re.compile(r"^rx-")),
    ("Zenoh send and links (tx, net)", re.compile(r"^(tx|net)-")),
    ("Zenoh accept and timers (acc)", re.compile(r"^acc-")),
    ("Zenoh app (app)", re.compile(r"^app-")),
)
PYTHON_THREADS = "Python threads (watchdog, token, system; main)"
OTHER = "other threads"


def thread_group(name: str, is_main: bool) -> str:
    """The row a thread's CPU is counted in, by its OS name (Zenoh names its threads)."""
    if is_main or name.startswith("python"):
        return PYTHON_THREADS
    for group, pattern in THREAD_GROUPS:
        if pattern.match(name):
            return group
    return OTHER


def sample_threads(pids: list[int]) -> dict[tuple[int, int], tuple[str, float, int]]:
    """(pid, tid) -> (group, CPU seconds, context switches) of every thread of ``pids``."""
    out: dict[tuple[int, int], tuple[str, float, int]] = {}
    for pid in pids:
        with contextlib.suppress(OSError):
            for tid_text in os.listdir(f"/proc/{pid}/task"):
                tid = int(tid_text)
                try:
                    stat = Path(f"/proc/{pid}/task/{tid}/stat").read_text()
                    status = Path(f"/proc/{pid}/task/{tid}/status").read_text()
                except OSError:
                    continue
                name = stat[stat.index("(") + 1 : stat.rindex(")")]
                fields = stat.rsplit(")", 1)[1].split()
                cpu = (int(fields[11]) + int(fields[12])) / CLOCK_TICKS
                switches = sum(
                    int(line.split()[1]) for line in status.splitlines() if "ctxt_switches:" in line
                )
                out[(pid, tid)] = (thread_group(name, tid == pid), cpu, switches)
    return out


def per_visit(
    before: dict[tuple[int, int], tuple[str, float, int]],
    after: dict[tuple[int, int], tuple[str, float, int]],
    visits: int,
    nodes: int,
) -> dict[str, float]:
    """µs of CPU per visit per node by thread group, plus ``context switches`` per visit per node."""
    cpu: dict[str, float] = {}
    switches: dict[str, int] = {}
    for key, (group, seconds, count) in after.items():
        _, seconds0, count0 = before.get(key, (group, 0.0, 0))
        cpu[group] = cpu.get(group, 0.0) + seconds - seconds0
        switches[group] = switches.get(group, 0) + count - count0
    per = visits * nodes
    out = {group: value / per * 1e6 for group, value in cpu.items()}
    out["total"] = sum(cpu.values()) / per * 1e6
    out["context switches"] = sum(switches.values()) / per
    for group, count in switches.items():  # which threads are woken per hop
        out[f"context switches: {group}"] = count / per
    return out


def perf_report(data: Path, sort: str) -> str:
    """``perf report``'s table of ``data``, sample counts by the ``sort`` keys (comm,dso,...)."""
    command = ["perf", "report", "-i", str(data), "--sort", sort, "-n", "--stdio", "-g", "none"]
    return subprocess.run(command, capture_output=True, text=True, check=False).stdout


def perf_split(data: Path, visits: int) -> dict[str, float]:
    """µs per visit of a node's ``perf record`` samples, by ``thread group / library`` (``visits``:
    the recorded nodes' visits together)."""
    out: dict[str, float] = {}
    for line in perf_report(data, "comm,dso").splitlines():
        parts = line.split()
        if len(parts) < 4 or not parts[0].endswith("%") or line.lstrip().startswith("#"):
            continue
        samples, comm, dso = int(parts[1]), parts[2], parts[3]
        group = thread_group(comm, comm.startswith("python")).split(" (")[0]
        library = dso.strip("[]").split(".")[0].split("-")[0]
        us = samples / PERF_HZ / visits * 1e6
        # Zenoh's threads do each other's work from run to run: the library totals compare better
        for key in (f"{group} / {library}", f"all threads / {library}"):
            out[key] = out.get(key, 0.0) + us
    return out


def perf_symbols(data: Path, visits: int) -> dict[str, float]:
    """µs per visit of the token's receiving thread in a node's ``perf record``, by function."""
    out: dict[str, float] = {}
    for line in perf_report(data, "comm,dso,sym").splitlines():
        parts = line.split(None, 5)
        if len(parts) < 6 or not parts[0].endswith("%") or not parts[2].startswith("rx-"):
            continue
        library = parts[3].strip("[]").split(".")[0].split("-")[0]
        symbol = parts[5].split("] ", 1)[-1][:60]
        key = f"{library}: {symbol}"
        out[key] = out.get(key, 0.0) + int(parts[1]) / PERF_HZ / visits * 1e6
    return out


def measure(
    kind: str, nodes: int, router: bool, window: float, perf_nodes: int, out_dir: Path
) -> dict[str, Any]:
    """One ring (``bare`` or ``ring``) of ``nodes``: its CPU per visit over one window, and
    ``perf record`` of ``perf_nodes`` of its nodes (0: none)."""
    perf = perf_nodes > 0
    perf_data = out_dir / f"{kind}-{nodes}-{time.monotonic_ns()}.data"
    perf_proc: subprocess.Popen | None = None
    if kind == "bare":
        bare = BareRing(nodes, router)
        try:
            bare.wait_circulating(60 + nodes)
            pids = bare.pids
            time.sleep(1.0)
            t0, before = time.monotonic(), sample_threads(pids)
            if perf:
                perf_proc = start_perf(pids[1 : 1 + perf_nodes], window, perf_data)
            time.sleep(window)
            t1, after = time.monotonic(), sample_threads(pids)
            if perf_proc is not None:
                perf_proc.wait()
        finally:
            stamps = bare.stop()
        visits = sum(1 for s in stamps if t0 <= s <= t1)
    else:
        visits, before, after, t0, t1, pids = ring_window(nodes, router, window, perf_nodes, perf_data)
    if visits < 10:
        raise RuntimeError(f"{kind} ring of {nodes}: only {visits} rounds in the window")
    result = {
        "kind": kind,
        "pids": pids,
        "visits": visits,
        "round_ms": (t1 - t0) / visits * 1e3,
        "per_visit_us": per_visit(before, after, visits, nodes),
        "load": [round(x, 2) for x in os.getloadavg()],
    }
    if perf and perf_data.exists():
        result["perf_nodes"] = perf_nodes
        result["perf_us"] = perf_split(perf_data, visits * perf_nodes)
        result["perf_rx_symbols_us"] = perf_symbols(perf_data, visits * perf_nodes)
        perf_data.unlink()
    return result


def start_perf(pids: list[int], window: float, data: Path) -> subprocess.Popen:
    """``perf record`` of the processes ``pids`` for ``window`` seconds into ``data``."""
    pid_list = ",".join(str(pid) for pid in pids)
    record = ["perf", "record", "-e", "cpu-clock", "-F", str(PERF_HZ), "-o", str(data), "-p", pid_list]
    return subprocess.Popen(
        [*record, "--", "sleep", str(window)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def ring_window(
    nodes: int, router: bool, window: float, perf_nodes: int, perf_data: Path
) -> tuple[int, Any, Any, float, float, list[int]]:
    """A tokenring ring of ``nodes`` (as ``tokenring bench`` runs it): visits and thread samples."""
    ring = LiveRing(nodes, router)
    try:
        ring.wait_circulating(60 + nodes)
        time.sleep(1.0)
        pids = ring.pids
        v0, t0, before = ring.visits(), time.monotonic(), sample_threads(pids)
        perf_proc = start_perf(pids[1 : 1 + perf_nodes], window, perf_data) if perf_nodes else None
        time.sleep(window)
        v1, t1, after = ring.visits(), time.monotonic(), sample_threads(pids)
        if perf_proc is not None:
            perf_proc.wait()
        return v1 - v0, before, after, t0, t1, pids
    finally:
        ring.stop()


def table(pairs: list[tuple[dict[str, Any], dict[str, Any]]], key: str) -> list[dict[str, Any]]:
    """Rows of ``key`` (per_visit_us or perf_us): ring, bare and their difference over the pairs."""
    names = sorted({name for ring, bare in pairs for name in (*ring.get(key, {}), *bare.get(key, {}))})
    rows = []
    for name in names:
        ring_values = [ring.get(key, {}).get(name, 0.0) for ring, _ in pairs]
        bare_values = [bare.get(key, {}).get(name, 0.0) for _, bare in pairs]
        diff = interval([r - b for r, b in zip(ring_values, bare_values, strict=True)])
        rows.append(
            {
                "part": name,
                "ring": sum(ring_values) / len(pairs),
                "bare": sum(bare_values) / len(pairs),
                "difference": diff,
            }
        )
    return sorted(rows, key=lambda row: -abs(row["difference"]["mean"]))


def format_rows(rows: list[dict[str, Any]], unit: str) -> str:
    lines = [f"{'':52} {'ring':>8} {'bare':>8} {'ring - bare':>12}  95 % interval"]
    for row in rows:
        d = row["difference"]
        ci = f"{d['lo']:+.1f} .. {d['hi']:+.1f}" if d["n"] > 1 else "(1 pair)"
        lines.append(
            f"{row['part'][:52]:52} {row['ring']:8.1f} {row['bare']:8.1f} {d['mean']:+12.1f}  {ci} {unit}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.hopcost",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--nodes", type=int, default=8, help="ring size (default 8)")
    parser.add_argument("--topology", choices=("peer", "router"), default="peer")
    parser.add_argument("--pairs", type=int, default=3, help="alternating bare/ring pairs (default 3)")
    parser.add_argument("--window", type=float, default=5.0, help="seconds measured per ring (default 5)")
    parser.add_argument("--perf", action="store_true", help="also perf-record one node per ring")
    parser.add_argument(
        "--perf-nodes", type=int, default=1, metavar="K", help="with --perf: record K nodes (default 1)"
    )
    parser.add_argument("--json", metavar="FILE", help="write the pairs and tables as JSON")
    args = parser.parse_args(argv)
    if not 2 <= args.nodes <= 255 or args.pairs < 1 or args.window <= 0:
        sys.stderr.write("hopcost: --nodes 2..255, --pairs >= 1, --window > 0\n")
        return 2
    if not 1 <= args.perf_nodes < args.nodes:
        sys.stderr.write(f"hopcost: --perf-nodes 1..{args.nodes - 1} (the nodes after the first)\n")
        return 2
    if args.json and Path(args.json).exists():
        sys.stderr.write(f"hopcost: {args.json} exists; not overwritten\n")
        return 2
    if args.perf and shutil.which("perf") is None:
        sys.stderr.write("hopcost: --perf needs perf (Debian: linux-perf)\n")
        return 2
    from tokenring.transport import use_host_runtime

    use_host_runtime()
    router = args.topology == "router"
    pairs: list[tuple[dict[str, Any], dict[str, Any]]] = []
    with tempfile.TemporaryDirectory(prefix="hopcost-") as tmp:
        for pair in range(args.pairs):
            got: dict[str, dict[str, Any]] = {}
            for kind in ("bare", "ring"):
                sys.stderr.write(
                    f"[pair {pair + 1}/{args.pairs}] {kind} ring of {args.nodes} ({args.topology}s) ...\n"
                )
                perf_nodes = args.perf_nodes if args.perf else 0
                got[kind] = measure(kind, args.nodes, router, args.window, perf_nodes, Path(tmp))
                sys.stderr.write(
                    f"    {got[kind]['visits']} rounds, {got[kind]['round_ms']:.3f} ms each, "
                    f"{got[kind]['per_visit_us']['total']:.1f} µs CPU per visit per node, load {got[kind]['load'][0]}\n"
                )
            pairs.append((got["ring"], got["bare"]))
    threads = table(pairs, "per_visit_us")
    print(
        f"CPU per visit per node, {args.nodes} nodes ({args.topology}s), {args.pairs} pairs of {args.window:g} s:"
    )
    print(format_rows(threads, "µs"))
    result: dict[str, Any] = {
        "nodes": args.nodes,
        "topology": args.topology,
        "pairs": pairs,
        "threads": threads,
    }
    if args.perf:
        split = table(pairs, "perf_us")
        print(f"\nperf samples of {args.perf_nodes} node(s) (thread / library), per visit of a node:")
        print(format_rows([row for row in split if abs(row["ring"]) + abs(row["bare"]) >= 0.5], "µs"))
        result["perf"] = split
        symbols = table(pairs, "perf_rx_symbols_us")[:30]
        print("\nthe token's receiving thread, by function (the 30 largest differences):")
        print(format_rows(symbols, "µs"))
        result["perf_rx_symbols"] = symbols
    if args.json:  # the tables and each run's thread figures; the perf samples' dicts stay out
        slim = [
            tuple({k: v for k, v in run.items() if not k.startswith("perf")} for run in pair)
            for pair in pairs
        ]
        Path(args.json).write_text(json.dumps({**result, "pairs": slim}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())
    sys.exit(130)
