"""Spurious token regenerations: the ring with no fault, for minutes, with and without a CPU hog.

Each configuration launches ``tokenring up`` (its own ring name and port), waits until the ring
circulates and the launcher has finished booting (programs loaded), optionally starts a CPU hog
on both cores (``stress-ng --cpu 2``, or two busy Python loops without it), and then watches the
ring for ``--minutes``: the nodes' ``tokens_regenerated`` (their sum's delta is the figure),
their regenerations by cause (tokenring/node/regeneration.py), main's round counter, the round times
of the highest node (rank 0: the first to regenerate a token it misses) against its
reconfiguration timeout, the load average, and the warnings the nodes log about the token.
No fault is injected: every regeneration here is spurious.

    python -m bench --sections spurious [--spurious-minutes 5] [--spurious-configs idle,idle+hog]
    python -m bench.spurious --minutes 5 --json bench/results/spurious-DATE.json

Configurations (``CONFIGS``): ``idle`` the default pace (2.5 Mbit/s, ``--speed 1``) with
``--no-world --no-programs``; ``robot`` the default pace with the world and the eight programs
(plain ``tokenring up``); ``speed10`` ``--speed 10`` with the world and the programs (the wire
at 25 Mbit/s). Each without and with the hog (``+hog``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
HIGHEST = 80  # charger: rank 0 of the eight, the first to regenerate a token it misses
POLL_S = 10.0  # stats and load every this many seconds
ROUNDS_POLL_S = 20.0  # the highest node's round times (it keeps the last 16384)
WARNINGS = re.compile(r"regenerat|did not acknowledge|frozen|rejoin|skipping|vanished", re.I)
MAX_LOG_LINES = 40  # warnings kept per configuration (the first ones)


@dataclass(frozen=True)
class Config:
    """One configuration: what ``tokenring up`` gets, and whether a CPU hog runs beside it."""

    key: str
    label: str
    up_args: tuple[str, ...]
    hog: bool


BASES = {
    "idle": ("default pace (2.5 Mbit/s), --no-world --no-programs", ("--no-world", "--no-programs")),
    "robot": ("default pace (2.5 Mbit/s, --speed 1), world + 8 programs", ()),
    "speed10": ("--speed 10 (wire 25 Mbit/s), world + 8 programs", ("--speed", "10")),
}
CONFIGS = [
    Config(f"{key}{'+hog' if hog else ''}", label + (", CPU hog on both cores" if hog else ""), args, hog)
    for key, (label, args) in BASES.items()
    for hog in (False, True)
]
DEFAULT_BASES = ("idle", "robot", "speed10")


def pick_configs(text: str | None) -> list[Config]:
    """Configurations by key, e.g. ``idle,idle+hog``; none given: every configuration."""
    from tokenring import UsageError

    if not text:
        return [c for c in CONFIGS if c.key.split("+")[0] in DEFAULT_BASES]
    wanted = [w.strip() for w in text.split(",") if w.strip()]
    out = [c for c in CONFIGS if c.key in wanted]
    unknown = [w for w in wanted if not any(c.key == w for c in CONFIGS)]
    if unknown or not out:
        raise UsageError(
            f"spurious configurations {unknown or wanted}: known {', '.join(c.key for c in CONFIGS)}"
        )
    return out


def per_hour(count: float, seconds: float) -> float | None:
    """``count`` in ``seconds`` as a rate per hour (None without time)."""
    from tokenring.host import per_hour as rate

    return rate(count, seconds)


# ---------------------------------------------------------------------------------------------
# the CPU hog


@contextlib.contextmanager
def cpu_hog(enabled: bool, seconds: float, cores: int = 2) -> Iterator[str | None]:
    """A CPU hog on ``cores`` cores while the block runs (stopped by PID, and by itself after
    ``seconds`` plus a minute should this process die first); yields what it is."""
    from tokenring.host import die_with_parent

    if not enabled:
        yield None
        return
    exe = shutil.which("stress-ng")
    if exe:
        cmd = [exe, "--cpu", str(cores), "--timeout", f"{int(seconds) + 60}s", "--quiet"]
        procs = [subprocess.Popen(cmd, stdout=subprocess.DEVNULL, preexec_fn=die_with_parent)]
        what = f"stress-ng --cpu {cores}"
    else:
        loop = [sys.executable, "-c", "while True: pass"]
        procs = [subprocess.Popen(loop, preexec_fn=die_with_parent) for _ in range(cores)]
        what = f"{cores} busy Python loops"
    try:
        yield what
    finally:
        for proc in procs:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)  # stress-ng stops its workers on SIGTERM
        for proc in procs:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)


# ---------------------------------------------------------------------------------------------
# one ring


class LogTail:
    """Reads the launcher's output on a thread: keeps the nodes' token warnings logged while
    ``recording`` is set (the measurement, not the boot or the shutdown), drops the rest."""

    def __init__(self, stream: Any) -> None:
        self.lines: list[str] = []
        self.matched = 0
        self.recording = threading.Event()
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream: Any) -> None:
        for line in stream:
            if self.recording.is_set() and WARNINGS.search(line):
                self.matched += 1
                if len(self.lines) < MAX_LOG_LINES:
                    self.lines.append(line.rstrip()[:200])

    def join(self) -> None:
        self._thread.join(timeout=5)


def node_stats(session: Any, ring: str) -> dict[int, dict[str, Any]]:
    """Each answering node's ``stats`` reply by ID."""
    from tokenring import keys
    from tokenring.transport import query

    out = {}
    for _, reply in query(session, keys.control(ring, "*", "stats"), timeout=2.0):
        if reply.get("ok"):
            out[reply["result"]["id"]] = reply["result"]
    return out


def wait_formed(session: Any, ring: str, ids: list[int], timeout: float, alive: Callable[[], bool]) -> None:
    """Until every node answers, sees all of them active, has had visits, and the launcher is done booting."""
    from tokenring import TokenRingError, keys
    from tokenring.transport import query

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not alive():
            raise TokenRingError("tokenring up exited before the ring formed")
        found = node_stats(session, ring)
        if set(found) >= set(ids) and all(
            set(ids) <= set(found[i]["active"]) and found[i]["stats"]["visits"] >= 5 for i in ids
        ):
            launcher = query(session, keys.control(ring, "launcher", "status"), timeout=1.0)
            if launcher and launcher[0][1].get("ok") and not launcher[0][1]["result"].get("booting"):
                return
        time.sleep(0.5)
    raise TokenRingError(f"ring {ring} did not form in {timeout:.0f} s")


def totals(found: dict[int, dict[str, Any]]) -> dict[str, int]:
    """Sums over the nodes: tokens_regenerated, regenerations by cause, and main's rounds."""
    out = {"tokens_regenerated": sum(n["stats"]["tokens_regenerated"] for n in found.values())}
    for cause in ("fault", "membership", "spurious"):
        out[cause] = sum(n.get("regenerations", {}).get(cause, 0) for n in found.values())
    main = min(found) if found else None
    out["rounds"] = found[main]["stats"]["rounds"] if main is not None else 0
    out["reconfigurations"] = sum(n["stats"]["reconfigurations"] for n in found.values())
    out["unacked_passes"] = sum(n["stats"]["unacked_passes"] for n in found.values())
    return out


def regeneration_details(found: dict[int, dict[str, Any]], since: float) -> list[dict[str, Any]]:
    """The regenerations after ``since`` (wall time) as the nodes' ledgers saw them, oldest
    first: node, cause, ms since its last visit, frames already queued for its token thread,
    rank, timeout (each node keeps its last 16)."""
    out = [
        {"node": n["name"], **r}
        for n in found.values()
        for r in n.get("regenerations", {}).get("recent", [])
        if isinstance(r, dict) and r.get("t", 0) >= since
    ]
    out.sort(key=lambda r: r["t"])
    for r in out:
        r["t_s"] = round(r.pop("t") - since, 3)
    return out[:MAX_LOG_LINES]


class GapWatch:
    """The highest node's round times between polls: how close they came to its reconfiguration timeout."""

    def __init__(self) -> None:
        self.gaps: list[float] = []
        self._visits: int | None = None

    def poll(self, session: Any, ring: str, visits: int) -> None:
        from tokenring import keys
        from tokenring.transport import query

        replies = query(session, keys.control(ring, HIGHEST, "rounds"), timeout=3.0)
        if not replies or not replies[0][1].get("ok"):
            return
        values = replies[0][1]["result"]
        if self._visits is not None:
            new = max(0, visits - self._visits)
            self.gaps += values[-new:] if new else []
        self._visits = visits

    def summary(self, recon_s: float) -> dict[str, Any]:
        gaps = np.array(self.gaps) if self.gaps else np.array([0.0])
        return {
            "samples": len(self.gaps),
            "median_ms": round(float(np.median(gaps)) * 1e3, 3),
            "p99_ms": round(float(np.percentile(gaps, 99)) * 1e3, 3),
            "p999_ms": round(float(np.percentile(gaps, 99.9)) * 1e3, 3),
            "max_ms": round(float(np.max(gaps)) * 1e3, 3),
            "over_half_recon": int(np.sum(gaps > recon_s / 2)),
            "over_recon": int(np.sum(gaps > recon_s)),
            "top_ms": [round(x * 1e3, 1) for x in sorted(self.gaps, reverse=True)[:5]],
        }


def run_config(
    config: Config, seconds: float, say: Callable[[str], None] = lambda _t: None
) -> dict[str, Any]:
    """One configuration: boot the ring, watch it for ``seconds`` with no fault, stop it; its record."""
    from tokenring import default_protocol, keys
    from tokenring.host import die_with_parent
    from tokenring.transport import free_port, make_config, open_session, query

    ids = [n.id for n in default_protocol().default_nodes]
    ring = f"spur{os.getpid()}{config.key.replace('+', 'h')}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    record: dict[str, Any] = {"key": config.key, "label": config.label, "up_args": list(config.up_args)}
    record["load_before"] = [round(x, 2) for x in os.getloadavg()]
    record["code"] = code_version()  # each configuration starts fresh processes from the tree
    with tempfile.TemporaryDirectory(prefix="tokenring-spurious-") as store:
        cmd = [sys.executable, "-m", "tokenring", "up", "--ring", ring, "--listen", endpoint]
        cmd += ["--store", store, *config.up_args]
        launcher = subprocess.Popen(
            cmd,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=REPO,
            preexec_fn=die_with_parent,  # its nodes die with it in turn
        )
        tail = LogTail(launcher.stdout)
        pids: list[int] = []
        try:
            with open_session(make_config(connect=[endpoint])) as session:
                t_boot = time.monotonic()
                wait_formed(session, ring, ids, 180.0, lambda: launcher.poll() is None)
                status = query(session, keys.control(ring, "launcher", "status"), timeout=2.0)
                pids = [n["pid"] for n in status[0][1]["result"]["nodes"]] if status else []
                record["boot_s"] = round(time.monotonic() - t_boot, 1)
                # the last join must lie outside the window in which the nodes' ledgers take a
                # regeneration for the consequence of a membership change
                found = node_stats(session, ring)
                settle = max(
                    (n.get("regenerations", {}).get("quiet_s", 0.0) for n in found.values()), default=0.0
                )
                time.sleep(settle)
                record["settle_s"] = settle
                with cpu_hog(config.hog, seconds) as hog:
                    record["hog"] = hog
                    tail.recording.set()
                    record.update(watch(session, ring, seconds, say))
                    tail.recording.clear()
        finally:
            record["log_warnings"] = tail.lines
            stop_launcher(launcher, pids)
            tail.join()
            record["log_warning_count"] = tail.matched
    record["load_after"] = [round(x, 2) for x in os.getloadavg()]
    return record


def watch(session: Any, ring: str, seconds: float, say: Callable[[str], None]) -> dict[str, Any]:
    """Watch a formed ring for ``seconds``: deltas of its counters, the samples, the round gaps."""
    first = node_stats(session, ring)
    t0 = time.monotonic()
    wall0 = time.time()
    base = totals(first)
    gaps = GapWatch()
    gaps.poll(session, ring, first.get(HIGHEST, {}).get("stats", {}).get("visits", 0))
    samples: list[dict[str, Any]] = []
    recon_ms: list[float] = []
    next_rounds = t0 + ROUNDS_POLL_S
    last = first
    reported = 0
    while True:
        now = time.monotonic()
        if now - t0 >= seconds:
            break
        time.sleep(min(POLL_S, seconds - (now - t0)))
        found = node_stats(session, ring)
        if not found:
            continue
        last = found
        now = time.monotonic()
        if HIGHEST in found and (now >= next_rounds or now - t0 >= seconds):
            gaps.poll(session, ring, found[HIGHEST]["stats"]["visits"])
            next_rounds = now + ROUNDS_POLL_S
        t = totals(found)
        main = found[min(found)]
        if HIGHEST in found:
            recon_ms.append(found[HIGHEST]["timeouts_ms"]["recon"])
        samples.append(
            {
                "t_s": round(now - t0, 1),
                "regenerated": t["tokens_regenerated"] - base["tokens_regenerated"],
                "spurious": t["spurious"] - base["spurious"],
                "rounds": t["rounds"] - base["rounds"],
                "round_ms_median": round(main["round_ms"]["median"], 3),
                "round_ms_p99": round(main["round_ms"]["p99"], 3),
                "load1": round(os.getloadavg()[0], 2),
            }
        )
        if samples[-1]["regenerated"] > reported:
            reported = samples[-1]["regenerated"]
            say(f"t={now - t0:.0f} s: {reported} regeneration(s) so far ({samples[-1]['spurious']} spurious)")
    duration = time.monotonic() - t0
    final = node_stats(session, ring) or last
    end = totals(final)
    delta = {k: end[k] - base[k] for k in base}
    recon = float(np.median(recon_ms)) if recon_ms else float("nan")
    loads = [s["load1"] for s in samples]
    return {
        "seconds": round(duration, 1),
        "rounds": delta["rounds"],
        "regenerated": delta["tokens_regenerated"],
        "by_cause": {k: delta[k] for k in ("fault", "membership", "spurious")},
        "per_hour": per_hour(delta["tokens_regenerated"], duration),
        "spurious_per_hour": per_hour(delta["spurious"], duration),
        "reconfigurations": delta["reconfigurations"],
        "unacked_passes": delta["unacked_passes"],
        "round_ms": {
            "median": round(float(np.median([s["round_ms_median"] for s in samples])), 3)
            if samples
            else None,
            "p99_max": round(max(s["round_ms_p99"] for s in samples), 3) if samples else None,
        },
        "recon_ms": {
            "median": round(recon, 1),
            "min": min(recon_ms, default=None),
            "max": max(recon_ms, default=None),
        },
        "gaps_at_highest": gaps.summary(recon / 1e3 if recon_ms else 1.0),
        "regenerations": regeneration_details(final, wall0),
        "load1": {
            "median": float(np.median(loads)) if loads else None,
            "max": max(loads, default=None),
        },
        "samples": samples,
    }


def stop_launcher(launcher: subprocess.Popen, pids: list[int]) -> None:
    """SIGTERM the launcher (it stops its nodes), then make sure every node PID is gone."""
    if launcher.poll() is None:
        launcher.send_signal(signal.SIGTERM)
        try:
            launcher.wait(30)
        except subprocess.TimeoutExpired:
            launcher.kill()
            launcher.wait(5)
    deadline = time.monotonic() + 5.0
    for pid in pids:
        while time.monotonic() < deadline and _alive(pid):
            time.sleep(0.05)
        if _alive(pid):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def code_version() -> str:
    """The commit the nodes run, with ``+`` and the changed files of tokenring/ if the tree differs."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        changed = subprocess.run(
            ["git", "status", "--porcelain", "--", "tokenring"],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.split("\n")
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    files = sorted(line[3:] for line in changed if line.strip())
    return head + (f"+{','.join(files)}" if files else "")


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


# ---------------------------------------------------------------------------------------------
# the section


def run(
    configs: list[Config],
    minutes: float,
    say: Callable[[str], None] = print,
    note: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Every configuration in turn; the section's record (compact: kilobytes)."""
    out: dict[str, Any] = {"minutes": minutes, "stress_ng": bool(shutil.which("stress-ng")), "runs": []}
    for config in configs:
        say(f"spurious: {config.label}, {minutes:g} min with no fault")
        try:
            record = run_config(config, minutes * 60.0, note)
        except Exception as exc:
            record = {"key": config.key, "label": config.label, "error": f"{type(exc).__name__}: {exc}"}
            note(f"failed: {record['error']}")
        else:
            note(describe(record))
        out["runs"].append(record)
    return out


def describe(r: dict[str, Any]) -> str:
    """One line per run: regenerations, rate, rounds, round time, gaps, load."""
    rate = r["per_hour"]
    g = r["gaps_at_highest"]
    details = r.get("regenerations", [])
    queued = sum(1 for d in details if d.get("queued"))
    return (
        f"{r['regenerated']} regenerations ({r['by_cause']['spurious']} spurious) in {r['seconds'] / 60:.1f} min "
        f"= {rate:.1f}/h; {r['rounds']} rounds, round median {r['round_ms']['median']} ms; "
        f"highest node's gaps: max {g['max_ms']} ms, {g['over_recon']} over the {r['recon_ms']['median']} ms "
        f"timeout; load median {r['load1']['median']}"
        + (
            f"; {queued} of {len(details)} with a token already queued at the regenerating node"
            if details
            else ""
        )
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.spurious", description=__doc__)
    parser.add_argument("--minutes", type=float, default=5.0, help="minutes per configuration")
    parser.add_argument("--configs", help=f"subset ({', '.join(c.key for c in CONFIGS)})")
    parser.add_argument("--json", help="write the record here")
    args = parser.parse_args(argv)
    from tokenring.transport import use_host_runtime

    use_host_runtime()
    result = run(pick_configs(args.configs), args.minutes)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 1 if any("error" in r for r in result["runs"]) else 0


if __name__ == "__main__":
    sys.exit(main())
